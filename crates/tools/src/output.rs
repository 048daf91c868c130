//! Output folders that are written whole or not at all: every tool writes into a fresh sibling
//! folder and swaps it in only when everything is there, so a failure leaves the previous `out`
//! untouched and no half-written one.

use std::path::{Path, PathBuf};

/// Files built in memory, (relative name, bytes), to be written together.
pub type Files = Vec<(String, Vec<u8>)>;

/// `.NAME.TAG-PID` beside `out`.
fn sibling(out: &Path, tag: &str) -> PathBuf {
    let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = out.file_name().map_or("out".into(), |n| n.to_string_lossy().into_owned());
    parent.join(format!(".{name}.{tag}-{}", std::process::id()))
}

/// An I/O error that names the path it concerns.
fn at(path: &Path, what: &str) -> impl FnOnce(std::io::Error) -> std::io::Error {
    let context = format!("{}: {what}", path.display());
    move |e| std::io::Error::new(e.kind(), format!("{context}: {e}"))
}

/// Creates the folder that will hold `out` (and its parents), naming the path on failure. Tools
/// call it before long work, so a bad `--out` fails at once rather than after the simulation.
pub fn make_parent(out: &Path) -> std::io::Result<()> {
    match out.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(parent) => std::fs::create_dir_all(parent).map_err(at(parent, "cannot create the output folder")),
        None => Ok(()),
    }
}

/// Writes one file whole or not at all: `write` fills a temporary sibling, which is renamed
/// onto `out` only when it succeeded. Missing parent folders are created.
pub fn write_file(out: &Path, write: impl FnOnce(&Path) -> std::io::Result<()>) -> std::io::Result<()> {
    make_parent(out)?;
    let tmp = sibling(out, "partial");
    if let Err(e) = write(&tmp).map_err(at(out, "cannot write")) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, out).map_err(at(out, "cannot replace"))
}

/// Runs `write` on an empty temporary folder beside `out`, then replaces `out` with it.
pub fn replace_folder<T, E: From<std::io::Error>>(
    out: &Path,
    write: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<T, E> {
    let (tmp, old) = (sibling(out, "tmp"), sibling(out, "old"));
    make_parent(out)?;
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).map_err(at(&tmp, "cannot create"))?;
    let value = match write(&tmp) {
        Ok(v) => v,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    if out.exists() {
        std::fs::rename(out, &old).map_err(at(out, "cannot move the previous output aside"))?;
    }
    std::fs::rename(&tmp, out).map_err(at(out, "cannot put the new output in place"))?;
    let _ = std::fs::remove_dir_all(&old);
    Ok(value)
}

/// Progress of long work. The command line shows it as a bar; tests and other callers pass
/// [`Silent`]. Keeps progress bars out of the library.
pub trait Progress: Sync {
    /// The work has `total` units.
    fn start(&self, _total: u64) {}
    /// Names what is running now.
    fn set_label(&self, _label: &str) {}
    /// `position` units are done.
    fn set_position(&self, _position: u64) {}
    /// The work is over (successfully or not).
    fn finish(&self) {}
}

/// Progress that is not shown.
pub struct Silent;

impl Progress for Silent {}
