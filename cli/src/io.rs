//! File edges of the CLI: `-` for stdin/stdout, and writes that never leave a half file.

use std::fs::File;
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
/// failure at any point (in `write` too) leaves whatever was at `path` untouched.
pub fn write_with<E: From<io::Error>>(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> Result<(), E>,
) -> Result<(), E> {
    if path == Path::new("-") {
        let mut out = io::stdout().lock();
        write(&mut out)?;
        return Ok(out.flush()?);
    }
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
