//! Independent items spread over threads (runs read, conditioned, simulated): each result lands in
//! its item's place, whichever thread finished first, so the output is the sequential one.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// `f` on every item, one worker per entry of `states` (each worker holds its state for every item
/// it takes: an FMU instance, or nothing), at most one per item; results in item order.
pub fn map_with<S: Send, T: Sync, R: Send>(
    states: &[Mutex<S>],
    items: &[T],
    f: impl Fn(&mut S, &T) -> R + Sync,
) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<R>>> = items.iter().map(|_| Mutex::new(None)).collect();
    let work = |state: &Mutex<S>| {
        let mut state = state.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= items.len() {
                break;
            }
            let r = f(&mut state, &items[i]);
            *results[i].lock().unwrap_or_else(|p| p.into_inner()) = Some(r);
        }
    };
    let workers = states.len().min(items.len());
    match workers {
        0 if items.is_empty() => {}
        0 => panic!("parallel::map_with: no worker state for {} items", items.len()),
        // one worker: on this thread, no spawn
        1 => work(&states[0]),
        _ => std::thread::scope(|s| {
            for state in &states[..workers] {
                s.spawn(|| work(state));
            }
        }),
    }
    results.into_iter().map(|m| m.into_inner().unwrap_or_else(|p| p.into_inner()).expect("every item ran")).collect()
}

/// `f` on every item over `threads` threads (at least one); results in item order.
pub fn map<T: Sync, R: Send>(threads: usize, items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let states: Vec<Mutex<()>> = (0..threads.max(1)).map(|_| Mutex::new(())).collect();
    map_with(&states, items, |_, item| f(item))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_keep_the_items_order_whatever_finishes_first() {
        let items: Vec<u64> = (0..40).collect();
        // the early items take longest, so later ones finish first
        let out = map(3, &items, |&i| {
            std::thread::sleep(std::time::Duration::from_micros(50 * (40 - i)));
            i * i
        });
        assert_eq!(out, items.iter().map(|i| i * i).collect::<Vec<_>>());
        assert_eq!(map(1, &items, |&i| i + 1), items.iter().map(|i| i + 1).collect::<Vec<_>>());
        assert!(map(4, &[] as &[u64], |&i| i).is_empty());
    }

    #[test]
    fn each_worker_keeps_its_own_state() {
        let states: Vec<Mutex<usize>> = (0..2).map(|_| Mutex::new(0)).collect();
        let items = vec![1usize; 100];
        let out = map_with(&states, &items, |count, &x| {
            *count += x;
            *count
        });
        assert_eq!(out.len(), 100);
        let done: usize = states.iter().map(|s| *s.lock().unwrap()).sum();
        assert_eq!(done, 100, "every item counted once, by one worker");
    }
}
