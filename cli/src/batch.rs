//! Many files in one call (`gsi encode a.png b.jpg -o out/`, a folder as input): the
//! plan (which input goes to which output), one progress bar for the whole batch, files
//! run a few at a time, and failures reported per file while the rest go on.
//!
//! Beyond one machine the CLI stays a per-file function: the README shows how an
//! existing engine (GNU parallel over ssh, a Ray or Spark map) spreads a file list.

use crate::Failure;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// One file of a batch.
#[derive(Clone, Debug)]
pub struct Job {
    pub input: PathBuf,
    pub output: PathBuf,
}

/// Whether the command line asks for a batch: several inputs, a folder as input, or an
/// output that is a folder (an existing one, or a path ending in a separator).
pub fn is_batch(inputs: &[PathBuf], output: Option<&Path>) -> bool {
    inputs.len() > 1
        || inputs.iter().any(|p| p.is_dir())
        || output.is_some_and(|o| {
            o.is_dir()
                || o.as_os_str()
                    .to_string_lossy()
                    .ends_with(std::path::MAIN_SEPARATOR)
        })
}

/// The inputs, with each folder replaced by its files whose extension is one of `exts`
/// (not recursing, sorted by name). A folder with no such file is an error, as is `-`.
pub fn expand(inputs: &[PathBuf], exts: &[&str]) -> Result<Vec<PathBuf>, Failure> {
    let mut files = Vec::new();
    for input in inputs {
        if input == Path::new("-") {
            return Err(Failure(
                "standard input (`-`) cannot be part of a batch".into(),
            ));
        }
        if !input.is_dir() {
            files.push(input.clone());
            continue;
        }
        let named = |e: std::io::Error| Failure(format!("{}: {e}", input.display()));
        let mut found = Vec::new();
        for entry in std::fs::read_dir(input).map_err(named)? {
            let path = entry.map_err(named)?.path();
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase);
            if path.is_file() && ext.is_some_and(|e| exts.contains(&e.as_str())) {
                found.push(path);
            }
        }
        if found.is_empty() {
            return Err(Failure(format!(
                "{}: no {} file in this folder",
                input.display(),
                exts.join("/")
            )));
        }
        found.sort();
        files.extend(found);
    }
    Ok(files)
}

/// Pair each input with `dir/<stem>.<ext>`. The folder is created if missing; two inputs
/// that would write the same output are refused before any work.
pub fn plan(inputs: Vec<PathBuf>, dir: &Path, ext: &str) -> Result<Vec<Job>, Failure> {
    if dir == Path::new("-") {
        return Err(Failure(
            "a batch writes a folder, not standard output (`-`)".into(),
        ));
    }
    std::fs::create_dir_all(dir).map_err(|e| Failure(format!("{}: {e}", dir.display())))?;
    let mut jobs: Vec<Job> = Vec::with_capacity(inputs.len());
    for input in inputs {
        let stem = input
            .file_stem()
            .ok_or_else(|| Failure(format!("{}: not a file name", input.display())))?;
        // `stem.ext`, not `with_extension`, which would cut `photo.v1` to `photo`.
        let mut name = stem.to_os_string();
        name.push(".");
        name.push(ext);
        let output = dir.join(name);
        // Where names differ only in case, a case-insensitive file system has one file.
        let same = |a: &Path, b: &Path| {
            if cfg!(any(target_os = "macos", target_os = "windows")) {
                a.to_string_lossy().to_lowercase() == b.to_string_lossy().to_lowercase()
            } else {
                a == b
            }
        };
        if let Some(other) = jobs.iter().find(|j| same(&j.output, &output)) {
            return Err(Failure(format!(
                "{} and {} would both write {}",
                other.input.display(),
                input.display(),
                output.display()
            )));
        }
        jobs.push(Job { input, output });
    }
    Ok(jobs)
}

/// What one file's work reports back: its summary line for the log.
pub type Done = Result<String, Failure>;

/// Run `work` on every job, `parallel` at a time, with one progress bar for the batch
/// (hidden when `quiet` or not on a terminal). `work` gets a callback to report its own
/// progress as a fraction in [0, 1]. Jobs for which `skip` gives a reason are not run
/// (the reason is printed). Each job's summary or error is one line on stderr; the
/// result is an error naming how many failed, if any did.
pub fn run<W>(
    jobs: &[Job],
    parallel: usize,
    quiet: bool,
    skip: impl Fn(&Job) -> Option<String> + Sync,
    work: W,
) -> Result<(), Failure>
where
    W: Fn(&Job, &(dyn Fn(f32) + Sync)) -> Done + Sync,
{
    const STEPS: u64 = 1000;
    let bar = crate::io::progress_bar(
        jobs.len() as u64 * STEPS,
        quiet,
        "{bar:30} {msg}  ETA {eta}",
    );
    // Each job's progress, in thousandths; the bar shows their sum.
    let progress: Vec<AtomicUsize> = jobs.iter().map(|_| AtomicUsize::new(0)).collect();
    let (next, finished, failed) = (
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
    );
    let log = Mutex::new(());
    let say = |line: String| {
        let _guard = log.lock().unwrap_or_else(|e| e.into_inner());
        bar.suspend(|| eprintln!("{line}"));
    };
    let total = jobs.len();
    let update = || {
        let sum: usize = progress.iter().map(|p| p.load(Ordering::Relaxed)).sum();
        bar.set_position(sum as u64);
        bar.set_message(format!(
            "{}/{total} files",
            finished.load(Ordering::Relaxed)
        ));
    };
    let worker = || loop {
        let k = next.fetch_add(1, Ordering::Relaxed);
        let Some(job) = jobs.get(k) else { break };
        let outcome = match skip(job) {
            Some(why) => Ok(format!("{}: skipped, {why}", job.output.display())),
            None => {
                let report = |f: f32| {
                    let f = if f.is_finite() {
                        f.clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    progress[k].store((f * STEPS as f32) as usize, Ordering::Relaxed);
                    update();
                };
                work(job, &report)
            }
        };
        progress[k].store(STEPS as usize, Ordering::Relaxed);
        finished.fetch_add(1, Ordering::Relaxed);
        update();
        match outcome {
            Ok(line) if !quiet => say(line),
            Ok(_) => {}
            Err(Failure(e)) => {
                failed.fetch_add(1, Ordering::Relaxed);
                say(format!("gsi: {e}"));
            }
        }
    };
    let parallel = parallel.clamp(1, total.max(1));
    std::thread::scope(|s| {
        for _ in 1..parallel {
            s.spawn(worker);
        }
        worker();
    });
    bar.finish_and_clear();
    match failed.into_inner() {
        0 => Ok(()),
        n => Err(Failure(format!("{n} of {total} files failed"))),
    }
}

/// The files a batch runs at once: `--jobs` when given (at least 1), else one on a GPU
/// (files would only queue for it) and [`default_parallel`] on the CPU.
pub fn parallel(jobs: Option<usize>, on_gpu: bool) -> Result<usize, Failure> {
    match (jobs, on_gpu) {
        (Some(0), _) => Err(Failure("--jobs must be at least 1".into())),
        (Some(n), _) => Ok(n),
        (None, true) => Ok(1),
        (None, false) => Ok(default_parallel()),
    }
}

/// The files at once a batch runs by default: one per core, at most four. Each file's
/// fit is itself parallel, but its serial parts (reading, initialization, colour solves,
/// quantization, writing) leave cores idle that another file fills: on the 2-core
/// machine, six Kodak files at 60 iterations took 33.4 s with two at once against 39.9 s
/// one at a time (medians of two runs, BENCHMARKS.md). At most four, so that a batch of
/// large photographs holds the memory of four fits, not of one per core.
pub fn default_parallel() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    cores.clamp(1, 4)
}
