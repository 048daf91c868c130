//! Output folders that are written whole or not at all: every tool writes into a fresh sibling
//! folder and swaps it in only when everything is there, so a failure leaves the previous `out`
//! untouched and no half-written one.

use std::path::{Path, PathBuf};

/// `.NAME.TAG-PID` beside `out`.
fn sibling(out: &Path, tag: &str) -> PathBuf {
    let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = out.file_name().map_or("out".into(), |n| n.to_string_lossy().into_owned());
    parent.join(format!(".{name}.{tag}-{}", std::process::id()))
}

/// Runs `write` on an empty temporary folder beside `out`, then replaces `out` with it.
pub fn replace_folder<T, E: From<std::io::Error>>(
    out: &Path,
    write: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<T, E> {
    let (tmp, old) = (sibling(out, "tmp"), sibling(out, "old"));
    if let Some(parent) = tmp.parent() {
        std::fs::create_dir_all(parent)?;
    }
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp)?;
    let value = match write(&tmp) {
        Ok(v) => v,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    if out.exists() {
        std::fs::rename(out, &old)?;
    }
    std::fs::rename(&tmp, out)?;
    let _ = std::fs::remove_dir_all(&old);
    Ok(value)
}
