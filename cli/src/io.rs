//! File edges of the CLI: `-` for stdin/stdout, and writes that never leave a half file.

use std::fs::{File, OpenOptions};
use std::io::{self, BufReader, Read, Write};
use std::path::{Path, PathBuf};

/// Open `path` for reading, or standard input for `-`.
pub fn open_input(path: &Path) -> io::Result<Box<dyn Read>> {
    if path == Path::new("-") {
        Ok(Box::new(BufReader::new(io::stdin().lock())))
    } else {
        Ok(Box::new(BufReader::new(File::open(path)?)))
    }
}

/// Write `bytes` to `path` (or standard output for `-`), as [`write_with`] does.
pub fn write_output(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_with(path, |out| out.write_all(bytes))
}

/// Write to `path` (or standard output for `-`) what `write` writes, as it writes it.
///
/// A file is written to a temporary sibling, synced, then renamed over the target, so a
/// failure at any point (in `write` too) leaves whatever was at `path` untouched. A
/// symbolic link is written through: the file it names is replaced and the link stays.
/// A target that is neither a file nor a folder (`/dev/null`, a FIFO, a terminal) is
/// written in place: renaming over it would put a regular file where the device was,
/// which for `/dev/null` run as root breaks every program on the machine.
pub fn write_with<E: From<io::Error>>(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> Result<(), E>,
) -> Result<(), E> {
    if path == Path::new("-") {
        let mut out = io::stdout().lock();
        write(&mut out)?;
        return Ok(out.flush()?);
    }
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        let mut out =
            io::BufWriter::with_capacity(1 << 16, OpenOptions::new().write(true).open(path)?);
        write(&mut out)?;
        return Ok(out.flush()?);
    }
    let path = &through_links(path)?;
    let tmp = temp_sibling(path);
    let result = (|| {
        // Buffered: encoders write in small pieces; large writes pass straight through.
        let mut f = io::BufWriter::with_capacity(1 << 16, File::create(&tmp)?);
        write(&mut f)?;
        let f = f.into_inner().map_err(io::IntoInnerError::into_error)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)?;
        // Make the rename itself durable where the platform allows syncing a directory.
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// `path` with its symbolic links followed to the file they name, which need not exist
/// yet (a dangling link is written through too, as a shell's `>` does).
fn through_links(path: &Path) -> io::Result<PathBuf> {
    let mut at = path.to_path_buf();
    // As many links as Linux follows in one path.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&at) {
            Ok(m) if m.file_type().is_symlink() => {
                // A relative target is relative to the link's folder; `join` keeps an
                // absolute one as it is.
                let target = std::fs::read_link(&at)?;
                at = match at.parent() {
                    Some(dir) => dir.join(target),
                    None => target,
                };
            }
            _ => return Ok(at),
        }
    }
    Err(io::Error::other(format!(
        "{}: too many levels of symbolic links",
        path.display()
    )))
}

/// `dir/.name.gsi-tmp-<pid>-<k>`: same folder (so the rename is atomic), hidden, unique
/// per process and per write (a batch writes several files at once).
fn temp_sibling(path: &Path) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static WRITES: AtomicU64 = AtomicU64::new(0);
    let k = WRITES.fetch_add(1, Ordering::Relaxed);
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(format!(".gsi-tmp-{}-{k}", std::process::id()));
    path.with_file_name(name)
}

/// The bar of one file's fit: iterations, the fit's own message, time left.
pub const ITERATIONS_BAR: &str = "{bar:30} {pos}/{len} it  {msg}  ETA {eta}";

/// The bar of a fit whose steps differ in cost: the share of the work done, the fit's own
/// message, time left.
pub const WORK_BAR: &str = "{bar:30} {percent:>3}%  {msg}  ETA {eta}";

/// A progress bar of `len` steps drawn with `template` on a terminal, hidden when `quiet`
/// or when standard error is not a terminal (logs and pipes get no control codes).
pub fn progress_bar(len: u64, quiet: bool, template: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    let bar = indicatif::ProgressBar::new(len);
    if !quiet && io::stderr().is_terminal() {
        bar.set_style(
            indicatif::ProgressStyle::with_template(template)
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
    } else {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

/// Print `text` and a newline on standard output. A reader that stops early (`gsi info f |
/// head`) closes the pipe: that ends the output quietly, where `println!` would panic.
pub fn print_line(text: &str) -> Result<(), crate::Failure> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(crate::Failure(format!("standard output: {e}")))
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh, empty folder for one test.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("gsi-io-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_file_is_replaced_whole_or_left_as_it_was() {
        let dir = scratch("file");
        let f = dir.join("out.bin");
        std::fs::write(&f, b"old").unwrap();
        let failed = write_with(&f, |out| {
            out.write_all(b"half")?;
            Err(io::Error::other("the encoder gave up"))
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read(&f).unwrap(), b"old");
        write_output(&f, b"new").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"new");
        assert_eq!(names(&dir), ["out.bin"], "no temporary file is left behind");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_is_written_through_and_stays_a_link() {
        let dir = scratch("link");
        let target = dir.join("target.bin");
        let link = dir.join("link.bin");
        std::fs::write(&target, b"old").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_output(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(names(&dir), ["link.bin", "target.bin"]);
        // A dangling link, relative, through a second link: its file is made.
        std::os::unix::fs::symlink("made.bin", dir.join("dangling.bin")).unwrap();
        std::os::unix::fs::symlink("dangling.bin", dir.join("twice.bin")).unwrap();
        write_output(&dir.join("twice.bin"), b"made").unwrap();
        assert_eq!(std::fs::read(dir.join("made.bin")).unwrap(), b"made");
        assert_eq!(
            names(&dir),
            [
                "dangling.bin",
                "link.bin",
                "made.bin",
                "target.bin",
                "twice.bin"
            ]
        );
        // A loop of links is refused, and nothing is written.
        std::os::unix::fs::symlink("loop.bin", dir.join("loop.bin")).unwrap();
        assert!(write_output(&dir.join("loop.bin"), b"x").is_err());
        assert_eq!(names(&dir).len(), 6);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `-o /dev/null` or a named pipe: the special file is written, never renamed over.
    #[cfg(unix)]
    #[test]
    fn a_pipe_is_written_in_place_and_stays_a_pipe() {
        use std::os::unix::fs::FileTypeExt;
        let dir = scratch("fifo");
        let fifo = dir.join("pipe");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success(), "mkfifo failed");
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_output(&fifo, b"through the pipe").unwrap();
        // Checked before joining: a reader left waiting on a replaced pipe never returns.
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        assert_eq!(names(&dir), ["pipe"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
