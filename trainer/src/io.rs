//! Writing output files: atomically (a reader or an interrupted writer never sees a truncated file),
//! only over regular files or new paths, and `-` for standard output.

use crate::error::{Error, Result};
use std::path::Path;

/// The output path that means standard output.
pub const STDOUT: &str = "-";

/// True for `--out -`: write to standard output instead of a file.
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == STDOUT
}

/// Writes `bytes` to a new temporary file beside `path`, syncs it, then renames it over `path`,
/// so an interrupted write never leaves a truncated file at `path`. Errors name `path`. The rename
/// would replace whatever is at `path` (a symlink, a FIFO, a device node), so only a regular file
/// or a new path is accepted; `-` writes to standard output.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    if is_stdout(path) {
        let mut out = std::io::stdout().lock();
        return out.write_all(bytes).and_then(|()| out.flush()).map_err(Error::Stdout);
    }
    check_existing_output(path)?;
    let dir = output_dir(path);
    let name = path.file_name().ok_or_else(|| Error::Path { path: path.to_path_buf(), reason: "not a file path".into() })?;
    let unique = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.tmp{}-{unique}", name.to_string_lossy(), std::process::id()));
    let written = std::fs::File::create_new(&tmp).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    let result = written.and_then(|()| std::fs::rename(&tmp, path));
    match result {
        Ok(()) => {
            // Make the rename itself durable where the platform allows.
            if let Ok(d) = std::fs::File::open(dir) {
                let _ = d.sync_all();
            }
            Ok(())
        }
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(Error::io(path, e))
        }
    }
}

/// The directory an output file goes into.
fn output_dir(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// What is already at an output path must be a regular file (replaced) or nothing: the atomic
/// rename would silently turn a symlink, FIFO or device node (`/dev/full`) into a regular file.
fn check_existing_output(path: &Path) -> Result<()> {
    let meta = match std::fs::symlink_metadata(path) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(Error::io(path, e)),
    };
    let kind = meta.file_type();
    let what = if kind.is_file() {
        return Ok(());
    } else if kind.is_symlink() {
        "a symbolic link"
    } else if kind.is_dir() {
        "a directory"
    } else {
        special_file_kind(&kind)
    };
    Err(Error::Path {
        path: path.to_path_buf(),
        reason: format!("is {what}; outputs are written only to regular files or new paths (give a file path, or `-` for standard output)"),
    })
}

#[cfg(unix)]
fn special_file_kind(kind: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_fifo() {
        "a FIFO"
    } else if kind.is_char_device() || kind.is_block_device() {
        "a device node"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_file_kind(_: &std::fs::FileType) -> &'static str {
    "not a regular file"
}

/// Fails early, before a long computation, if `path` could not be written at the end: its
/// directory is missing or not writable (a probe file is created and removed there), or something
/// other than a regular file is at `path`. `-` (standard output) always passes.
pub fn check_output(path: &Path) -> Result<()> {
    if is_stdout(path) {
        return Ok(());
    }
    let dir = output_dir(path);
    if !dir.is_dir() {
        return Err(Error::Path { path: path.to_path_buf(), reason: format!("the directory {} does not exist", dir.display()) });
    }
    check_existing_output(path)?;
    let probe = dir.join(format!(".cbd-write-probe-{}", std::process::id()));
    match std::fs::File::create_new(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::Path { path: path.to_path_buf(), reason: format!("the directory {} is not writable: {e}", dir.display()) }),
    }
}
