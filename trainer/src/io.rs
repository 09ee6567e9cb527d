//! Writing output files: atomically (a reader or an interrupted writer never sees a truncated file),
//! only over regular files or new paths, never over a file the run reads, and `-` for standard output.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Which of the process's streams a message line was meant for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    /// A command's results (`outln!`).
    Out,
    /// Diagnostics: warnings, progress, what the pipeline chose (`errln!`).
    Err,
}

/// A program's own destination for the crate's message lines.
pub type MessageSink = Box<dyn Fn(Stream, &str) + Send + Sync>;

/// Set by a program that embeds the trainer (the Python package sends the lines to `logging`, never
/// to the interpreter's stdout); `None`, the `cbd` binary's case: stdout and stderr.
static SINK: std::sync::RwLock<Option<MessageSink>> = std::sync::RwLock::new(None);

/// Sends every later message line of this process to `sink` (`None`: back to stdout and stderr).
pub fn set_message_sink(sink: Option<MessageSink>) {
    *SINK.write().unwrap_or_else(|e| e.into_inner()) = sink;
}

/// Gives one message line to the sink, if one is set; false when there is none (the caller writes it).
pub fn to_sink(stream: Stream, line: std::fmt::Arguments<'_>) -> bool {
    let sink = SINK.read().unwrap_or_else(|e| e.into_inner());
    match sink.as_ref() {
        Some(sink) => {
            sink(stream, &line.to_string());
            true
        }
        None => false,
    }
}

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
///
/// Within [`with_staged_outputs`] (every `cbd` command) the file is only staged: written and synced
/// beside `path`, and renamed over it when the command succeeds; a command that fails later leaves
/// whatever was at `path` as it was.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    if is_stdout(path) {
        let mut out = std::io::stdout().lock();
        return out.write_all(bytes).and_then(|()| out.flush()).map_err(Error::Stdout);
    }
    check_existing_output(path)?;
    refuse_input(path)?;
    let dir = output_dir(path);
    let name = path.file_name().ok_or_else(|| Error::Path { path: path.to_path_buf(), reason: "not a file path".into() })?;
    let tmp = temporary_name(dir, name);
    if STAGED.with(|s| s.borrow().is_some()) {
        let staged = match unnamed_file(dir, bytes) {
            Some(Ok(file)) => Staged { path: path.to_path_buf(), tmp, unnamed: Some(file) },
            Some(Err(e)) => return Err(Error::io(path, e)),
            None => match write_named(&tmp, bytes) {
                Ok(()) => Staged { path: path.to_path_buf(), tmp, unnamed: None },
                Err(e) => {
                    let _ = std::fs::remove_file(&tmp);
                    return Err(Error::io(path, e));
                }
            },
        };
        STAGED.with(|s| {
            let mut s = s.borrow_mut();
            let outputs = &mut s.as_mut().expect("staging checked above").files;
            // A second write of the same output replaces the first.
            if let Some(k) = outputs.iter().position(|o| same_output(&o.path, path)) {
                outputs.remove(k).discard();
            }
            outputs.push(staged);
        });
        return Ok(());
    }
    let result = match unnamed_file(dir, bytes) {
        Some(file) => file.and_then(|f| link_unnamed(&f, &tmp)),
        None => write_named(&tmp, bytes),
    }
    .and_then(|()| std::fs::rename(&tmp, path));
    match result {
        Ok(()) => {
            sync_dir(dir);
            Ok(())
        }
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(Error::io(path, e))
        }
    }
}

/// Makes a rename in `dir` durable where the platform allows.
fn sync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// An output written and synced but not yet at its path ([`write_atomically`] within
/// [`with_staged_outputs`]).
struct Staged {
    path: PathBuf,
    /// The hidden name beside `path` the file takes on its way there.
    tmp: PathBuf,
    /// The unnamed file (Linux `O_TMPFILE`) holding the bytes, or `None` when they are at `tmp`.
    unnamed: Option<std::fs::File>,
}

impl Staged {
    /// Puts the file at its path.
    fn commit(&self) -> std::io::Result<()> {
        if let Some(f) = &self.unnamed {
            link_unnamed(f, &self.tmp)?;
        }
        std::fs::rename(&self.tmp, &self.path).inspect_err(|_| {
            let _ = std::fs::remove_file(&self.tmp);
        })
    }

    /// Drops the file: nothing at `path` changes.
    fn discard(self) {
        if self.unnamed.is_none() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }

    /// The staged bytes.
    fn read(&self) -> std::io::Result<Vec<u8>> {
        match &self.unnamed {
            Some(f) => {
                use std::io::{Read, Seek};
                let mut f = f;
                f.seek(std::io::SeekFrom::Start(0))?;
                let mut bytes = Vec::new();
                f.read_to_end(&mut bytes)?;
                Ok(bytes)
            }
            None => std::fs::read(&self.tmp),
        }
    }
}

/// What a command has written so far ([`with_staged_outputs`]).
#[derive(Default)]
struct Outputs {
    files: Vec<Staged>,
    /// Directories made for the outputs (`--plots DIR`), outermost first: removed again, when
    /// empty, if the command fails.
    dirs: Vec<PathBuf>,
}

std::thread_local! {
    /// The outputs of the command running on this thread, while one runs.
    static STAGED: std::cell::RefCell<Option<Outputs>> = const { std::cell::RefCell::new(None) };
}

/// Runs `command` with its outputs staged: every file [`write_atomically`] writes (standard output
/// aside) is held, written and synced beside its path, until `command` returns; then all are
/// renamed into place if it succeeded, or dropped if it failed (or panicked), so that a failing
/// command leaves every output path as it found it. Nested calls join the outer one.
pub fn with_staged_outputs<R>(command: impl FnOnce() -> Result<R>) -> Result<R> {
    if STAGED.with(|s| s.borrow().is_some()) {
        return command();
    }
    /// Drops what is staged if `command` unwinds.
    struct Guard;
    impl Drop for Guard {
        fn drop(&mut self) {
            if let Some(outputs) = STAGED.with(|s| s.borrow_mut().take()) {
                discard(outputs);
            }
        }
    }
    STAGED.with(|s| *s.borrow_mut() = Some(Outputs::default()));
    let guard = Guard;
    let result = command();
    let outputs = STAGED.with(|s| s.borrow_mut().take()).unwrap_or_default();
    drop(guard);
    match result {
        Ok(r) => commit(outputs).map(|()| r),
        Err(e) => {
            discard(outputs);
            Err(e)
        }
    }
}

/// Renames every staged file into place, once each path is found still fit to take it.
fn commit(outputs: Outputs) -> Result<()> {
    if let Some(e) = outputs.files.iter().find_map(|o| check_existing_output(&o.path).err()) {
        discard(outputs);
        return Err(e);
    }
    let mut files = outputs.files.into_iter();
    for output in files.by_ref() {
        if let Err(e) = output.commit() {
            files.for_each(Staged::discard);
            return Err(Error::io(&output.path, e));
        }
        sync_dir(output_dir(&output.path));
    }
    Ok(())
}

fn discard(outputs: Outputs) {
    outputs.files.into_iter().for_each(Staged::discard);
    for dir in outputs.dirs.iter().rev() {
        let _ = std::fs::remove_dir(dir);
    }
}

/// The bytes a command has written to `path` so far: the staged file's
/// ([`with_staged_outputs`]), else what is on disk.
pub fn read_output(path: &Path) -> Result<Vec<u8>> {
    let staged = STAGED.with(|s| s.borrow().as_ref().and_then(|o| o.files.iter().find(|f| same_output(&f.path, path)).map(Staged::read)));
    match staged {
        Some(bytes) => bytes.map_err(|e| Error::io(path, e)),
        None => std::fs::read(path).map_err(|e| Error::io(path, e)),
    }
}

/// Makes the directory `dir` (and its missing parents) for a command's outputs; within
/// [`with_staged_outputs`], the directories made are removed again (when empty) if it fails.
pub fn create_output_dir(dir: &Path) -> Result<()> {
    let mut missing = Vec::new();
    let mut at = Some(dir);
    while let Some(d) = at.filter(|d| !d.as_os_str().is_empty() && !d.exists()) {
        missing.push(d.to_path_buf());
        at = d.parent();
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    STAGED.with(|s| {
        if let Some(o) = s.borrow_mut().as_mut() {
            o.dirs.extend(missing.into_iter().rev());
        }
    });
    Ok(())
}

/// A hidden name beside the output, unique to this process and write.
fn temporary_name(dir: &Path, name: &std::ffi::OsStr) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let unique = COUNTER.fetch_add(1, Ordering::Relaxed);
    dir.join(format!(".{}.tmp{}-{unique}", name.to_string_lossy(), std::process::id()))
}

/// Writes `bytes` to a new file at `tmp` and syncs it.
fn write_named(tmp: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let mut f = std::fs::File::create_new(tmp)?;
    f.write_all(bytes)?;
    f.sync_all()
}

/// Writes and syncs `bytes` in an unnamed file of `dir` (Linux `O_TMPFILE`), named later
/// ([`link_unnamed`]): a process killed while writing (a 76 MB simulation takes a while) or before
/// its command ends leaves no hidden file behind, since a file without a name is freed with the
/// process. `None` where the kernel or file system has no unnamed files (the caller writes a named one).
#[cfg(target_os = "linux")]
fn unnamed_file(dir: &Path, bytes: &[u8]) -> Option<std::io::Result<std::fs::File>> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new().read(true).write(true).custom_flags(libc::O_TMPFILE).mode(0o666).open(dir).ok()?;
    Some(f.write_all(bytes).and_then(|()| f.sync_all()).map(|()| f))
}

/// Gives the unnamed file `f` the name `tmp`.
#[cfg(target_os = "linux")]
fn link_unnamed(f: &std::fs::File, tmp: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    use std::os::unix::io::AsRawFd;
    let fd_path = std::ffi::CString::new(format!("/proc/self/fd/{}", f.as_raw_fd())).map_err(std::io::Error::other)?;
    let name = std::ffi::CString::new(tmp.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    // SAFETY: both are NUL-terminated paths that outlive the call; linkat only reads them.
    let linked = unsafe { libc::linkat(libc::AT_FDCWD, fd_path.as_ptr(), libc::AT_FDCWD, name.as_ptr(), libc::AT_SYMLINK_FOLLOW) };
    if linked == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn unnamed_file(_: &Path, _: &[u8]) -> Option<std::io::Result<std::fs::File>> {
    None
}

#[cfg(not(target_os = "linux"))]
fn link_unnamed(_: &std::fs::File, _: &Path) -> std::io::Result<()> {
    Err(std::io::Error::other("no unnamed files on this platform"))
}

/// A file the run reads: device and inode (the same file under another name or a hard link is
/// still that file), the path it was read at, and how the command line named it.
struct Input {
    id: (u64, u64),
    path: PathBuf,
    name: String,
}

impl Input {
    /// Whether `id` is this input's file: the same device and inode, and the input still there
    /// (a deleted input's inode may come back as another file, which is then no input).
    fn is(&self, id: (u64, u64)) -> bool {
        self.id == id && file_id(&self.path) == Some(id)
    }
}

/// Every input noted so far ([`note_input`]).
static INPUTS: Mutex<Vec<Input>> = Mutex::new(Vec::new());

#[cfg(unix)]
fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn file_id(path: &Path) -> Option<(u64, u64)> {
    let _ = path;
    None
}

/// Notes `path` as an input of this run, `name` (a flag, or what the file is) naming it in
/// messages: no output of the run may replace it ([`write_atomically`] refuses to).
pub fn note_input(name: &str, path: &Path) {
    let Some(id) = file_id(path) else { return };
    let mut inputs = INPUTS.lock().unwrap_or_else(|e| e.into_inner());
    if !inputs.iter().any(|i| i.is(id)) {
        inputs.push(Input { id, path: path.to_path_buf(), name: name.to_string() });
    }
}

/// Forgets the inputs noted so far. A program that runs several commands in one process (the
/// Python package) starts each afresh: the inode of a deleted input may come back as a new output's.
pub fn forget_inputs() {
    INPUTS.lock().unwrap_or_else(|e| e.into_inner()).clear();
}

/// An output at `path` would replace a file the run reads: refused, naming the input.
fn refuse_input(path: &Path) -> Result<()> {
    let Some(id) = file_id(path) else { return Ok(()) };
    let inputs = INPUTS.lock().unwrap_or_else(|e| e.into_inner());
    match inputs.iter().find(|i| i.is(id)) {
        Some(input) => Err(Error::Path {
            path: path.to_path_buf(),
            reason: format!("is also an input ({}); writing there would replace it: give the output another path", input.name),
        }),
        None => Ok(()),
    }
}

/// A command's paths, checked before any work: each output can be written ([`check_output`]), is
/// none of the inputs (which are noted for the writes to come: each figure under `--plots` is held
/// to the same rule) and is not another output's file. Each path comes with its flag.
pub fn check_paths(inputs: &[(&str, Option<&Path>)], outputs: &[(&str, Option<&Path>)]) -> Result<()> {
    for (flag, path) in inputs {
        if let Some(path) = path {
            note_input(flag, path);
            // A model file's URDF is read too, after these checks: noted now, so an output on it
            // is refused before the work, not after it.
            if *flag == "--model" {
                if let Some(urdf) = urdf_of_model(path) {
                    note_input("--model's URDF", &urdf);
                }
            }
        }
    }
    let outputs: Vec<(&str, &Path)> = outputs.iter().filter_map(|(flag, path)| path.map(|p| (*flag, p))).collect();
    for (k, (flag, path)) in outputs.iter().enumerate() {
        check_output(path)?;
        refuse_input(path)?;
        if let Some((other, _)) = outputs[..k].iter().find(|(_, earlier)| same_output(earlier, path)) {
            return Err(Error::Path {
                path: path.to_path_buf(),
                reason: format!("is given to both {other} and {flag}; give each output its own path"),
            });
        }
    }
    Ok(())
}

/// The URDF a model file names (`[urdf] path`, relative to the file), if it reads one; `None` for
/// any file that is not such a model file (its own errors come when it is loaded).
fn urdf_of_model(model: &Path) -> Option<std::path::PathBuf> {
    use std::io::Read;
    let mut text = String::new();
    std::fs::File::open(model).ok()?.take(1 << 20).read_to_string(&mut text).ok()?;
    let table: toml::Table = toml::from_str(&text).ok()?;
    let path = Path::new(table.get("urdf")?.get("path")?.as_str()?);
    Some(if path.is_absolute() { path.to_path_buf() } else { model.parent().unwrap_or(Path::new("")).join(path) })
}

/// Whether two output paths name the same destination: both standard output, the same existing
/// file, or the same path once made absolute.
fn same_output(a: &Path, b: &Path) -> bool {
    if is_stdout(a) || is_stdout(b) {
        return is_stdout(a) && is_stdout(b);
    }
    match (file_id(a), file_id(b)) {
        (Some(x), Some(y)) => x == y,
        _ => std::path::absolute(a).ok() == std::path::absolute(b).ok(),
    }
}

/// A directory the run writes figures into (`--plots`), checked before any work: a writable
/// directory, or missing with a writable directory as its nearest existing ancestor (it is made).
pub fn check_output_dir(flag: &str, dir: &Path) -> Result<()> {
    let mut existing = dir;
    while !existing.as_os_str().is_empty() && std::fs::symlink_metadata(existing).is_err() {
        existing = existing.parent().unwrap_or(Path::new(""));
    }
    let existing = if existing.as_os_str().is_empty() { Path::new(".") } else { existing };
    match std::fs::metadata(existing) {
        Ok(meta) if meta.is_dir() => {}
        _ => {
            let what = if existing == dir { "is not a directory" } else { "cannot be made: a parent is not a directory" };
            return Err(Error::Path {
                path: dir.to_path_buf(),
                reason: format!("{what} ({flag} names the directory figures are written into)"),
            });
        }
    }
    let probe = existing.join(format!(".cbd-write-probe-{}", std::process::id()));
    match std::fs::File::create_new(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(Error::Path {
            path: dir.to_path_buf(),
            reason: format!(
                "the directory {} is not writable: {e} ({flag} names the directory figures are written into)",
                existing.display()
            ),
        }),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The inputs noted are the process's: tests that note or write files take turns, and forget
    /// their inputs when done (a deleted input's inode comes back as another test's file).
    static FILES: Mutex<()> = Mutex::new(());

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("cbd-io-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Issue 27 item 7: the data goes to an unnamed file first; the directory then holds the output
    /// only, replaced whole.
    #[test]
    fn atomic_write_leaves_only_the_output() {
        let _turn = FILES.lock().unwrap_or_else(|e| e.into_inner());
        let dir = scratch("atomic");
        let out = dir.join("a.txt");
        write_atomically(&out, b"first").unwrap();
        write_atomically(&out, b"second").unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"second");
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.txt")]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Issue 27 item 6: an output that is an input (the same file by any name) or another output is refused.
    #[test]
    fn outputs_are_neither_inputs_nor_each_other() {
        let _turn = FILES.lock().unwrap_or_else(|e| e.into_inner());
        let dir = scratch("inputs");
        let (data, link) = (dir.join("data.csv"), dir.join("link.csv"));
        std::fs::write(&data, b"q1,q2,x,y\n").unwrap();
        std::fs::hard_link(&data, &link).unwrap();
        let e = check_paths(&[("--data", Some(&data))], &[("--out", Some(&link))]).unwrap_err().to_string();
        assert!(e.contains("link.csv: is also an input (--data)"), "{e}");
        // Noted inputs hold for later writes too (each figure of --plots).
        assert!(write_atomically(&data, b"x").unwrap_err().to_string().contains("is also an input"));
        assert_eq!(std::fs::read(&data).unwrap(), b"q1,q2,x,y\n");
        let new = dir.join("new.blob");
        let e = check_paths(&[], &[("--out", Some(&new)), ("--json", Some(&dir.join(".").join("new.blob")))]).unwrap_err().to_string();
        assert!(e.contains("is given to both --out and --json"), "{e}");
        let dash = Path::new(STDOUT);
        assert!(check_paths(&[], &[("--out", Some(dash)), ("--json", Some(dash))]).is_err());
        assert!(check_paths(&[("--data", Some(&data))], &[("--out", Some(&new)), ("--json", None)]).is_ok());
        forget_inputs();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An input that is gone from its path is no input any more: its inode, which the file system
    /// may give to a new file (here: the same file renamed away), does not refuse that file's write.
    /// (Tests running beside this module's, which read model files from scratch folders they then
    /// delete, once made `atomic_write_leaves_only_the_output` refuse its own output.)
    #[test]
    fn an_input_gone_from_its_path_refuses_nothing() {
        let _turn = FILES.lock().unwrap_or_else(|e| e.into_inner());
        let dir = scratch("gone");
        let (read, moved) = (dir.join("model.toml"), dir.join("moved.txt"));
        std::fs::write(&read, b"name = \"x\"\n").unwrap();
        note_input("the model file", &read);
        assert!(write_atomically(&read, b"x").unwrap_err().to_string().contains("is also an input (the model file)"));
        std::fs::rename(&read, &moved).unwrap();
        write_atomically(&moved, b"an output").unwrap();
        assert_eq!(std::fs::read(&moved).unwrap(), b"an output");
        forget_inputs();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Issue 51 class 2: within a command, outputs are staged; a failure (or a panic) leaves every
    /// path as it was and no file or directory behind; success puts them all in place.
    #[test]
    fn staged_outputs_reach_their_paths_only_when_the_command_succeeds() {
        let _turn = FILES.lock().unwrap_or_else(|e| e.into_inner());
        let dir = scratch("staged");
        let (a, b) = (dir.join("a.json"), dir.join("b.urdf"));
        std::fs::write(&a, b"old a").unwrap();
        let plots = dir.join("plots").join("inner");
        let failed: Result<()> = with_staged_outputs(|| {
            write_atomically(&a, b"new a")?;
            create_output_dir(&plots)?;
            write_atomically(&plots.join("f.svg"), b"figure")?;
            write_atomically(&b, b"first b")?;
            write_atomically(&b, b"second b")?;
            assert_eq!(read_output(&b)?, b"second b");
            assert_eq!(std::fs::read(&a).unwrap(), b"old a", "nothing in place before the end");
            Err(Error::InvalidInput("late".into()))
        });
        assert!(failed.is_err());
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.json")]);
        assert_eq!(std::fs::read(&a).unwrap(), b"old a");
        let panicked = std::panic::catch_unwind(|| {
            let _ = with_staged_outputs(|| -> Result<()> {
                write_atomically(&a, b"new a").unwrap();
                panic!("a bug")
            });
        });
        assert!(panicked.is_err());
        assert_eq!(std::fs::read(&a).unwrap(), b"old a");
        with_staged_outputs(|| {
            write_atomically(&a, b"new a")?;
            with_staged_outputs(|| write_atomically(&b, b"b"))?;
            create_output_dir(&plots)?;
            write_atomically(&plots.join("f.svg"), b"figure")
        })
        .unwrap();
        assert_eq!((std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap()), (b"new a".to_vec(), b"b".to_vec()));
        assert_eq!(std::fs::read(plots.join("f.svg")).unwrap(), b"figure");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 3, "no temporary file left");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
