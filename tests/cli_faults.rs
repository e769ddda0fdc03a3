//! `volgen train` under faults: killed (SIGKILL) at random moments, checkpoint writes
//! included, and resumed each time; and a file-size limit (a full disk as a writer sees it).
//! Either way the run ends with the weights of an uninterrupted run.

mod common;

use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use candle_core::Device;
use common::{failure, ok, path, stones_dataset};
use rand::{Rng, SeedableRng};
use singrav::checkpoint::Checkpoint;
use singrav::RunDir;

/// `volgen train` of the micro preset with a checkpoint after every iteration, so kills and
/// full disks meet checkpoint writes often; `--resume` once the run directory exists (as a user
/// would after a kill; one killed before its first checkpoint starts over).
fn train_command(data: &Path, run: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_volgen"));
    command.args([
        "train",
        path(data),
        "--out",
        path(run),
        "--preset",
        "micro",
        "--set",
        "run.checkpoint_iterations=1",
    ]);
    if run.is_dir() {
        command.arg("--resume");
    }
    command
}

/// Every tensor of `run`'s checkpoint, as bits.
fn checkpoint_bits(run: &Path) -> Vec<(String, Vec<u32>)> {
    let checkpoint = Checkpoint::load(&RunDir::new(run).checkpoint(), &Device::Cpu).unwrap();
    let mut tensors: Vec<(String, Vec<u32>)> = checkpoint
        .tensors
        .iter()
        .map(|(name, t)| {
            let values: Vec<f32> = t.flatten_all().unwrap().to_vec1().unwrap();
            (name.clone(), values.iter().map(|v| v.to_bits()).collect())
        })
        .collect();
    tensors.sort();
    tensors
}

/// The names of the files a user sees in `run` (hidden temporary files left by a kill aside).
fn visible_files(run: &Path) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for entry in std::fs::read_dir(run).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if !name.starts_with('.') {
            names.insert(name);
        }
    }
    names
}

/// Lines of `run`'s loss log; each must be a whole JSON object.
fn log_lines(run: &Path) -> usize {
    let text = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    for line in text.lines() {
        serde_json::from_str::<serde_json::Value>(line)
            .unwrap_or_else(|e| panic!("log line `{line}`: {e}"));
    }
    text.lines().count()
}

/// The uninterrupted run the faulty ones must end equal to; returns its directory.
fn uninterrupted(root: &Path, data: &Path) -> std::path::PathBuf {
    let run = root.join("whole");
    ok(&train_command(data, &run).output().unwrap());
    run
}

#[test]
fn killed_at_random_moments_and_resumed_ends_with_the_uninterrupted_weights() {
    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(tmp.path());
    let whole = uninterrupted(tmp.path(), &data);
    let iterations = log_lines(&whole);

    // Ten kills, each once the log shows a randomly drawn iteration (spread over the whole run)
    // plus a random few milliseconds, so some land inside checkpoint writes.
    let run = tmp.path().join("killed");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut targets: Vec<usize> = (0..10).map(|_| rng.random_range(0..iterations)).collect();
    targets.sort_unstable();
    let mut killed_alive = 0;
    for target in targets {
        let mut child = train_command(&data, &run)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let done = std::fs::read_to_string(run.join("log.jsonl"))
                .map(|log| log.lines().count() >= target)
                .unwrap_or(false);
            if done || child.try_wait().unwrap().is_some() || Instant::now() > deadline {
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_micros(rng.random_range(0..20_000)));
        // SIGKILL: no destructor, no flush, no clean-up.
        if child.try_wait().unwrap().is_none() {
            child.kill().unwrap();
            killed_alive += 1;
        }
        child.wait().unwrap();
    }
    // The kills met running trainings (not only finished ones).
    assert!(
        killed_alive >= 8,
        "only {killed_alive} of 10 kills met a running training"
    );
    ok(&train_command(&data, &run).output().unwrap());

    assert_eq!(checkpoint_bits(&run), checkpoint_bits(&whole));
    assert_eq!(log_lines(&run), iterations);
    assert_eq!(visible_files(&run), visible_files(&whole));
}

#[cfg(unix)]
#[test]
fn a_full_disk_names_the_file_and_its_size_and_keeps_the_last_checkpoint() {
    use std::os::unix::process::CommandExt;

    let tmp = tempfile::tempdir().unwrap();
    let data = stones_dataset(tmp.path());
    let whole = uninterrupted(tmp.path(), &data);
    // A file-size limit between the smallest and the largest checkpoint of the run: the first
    // checkpoints fit, a later (larger) one does not.
    let final_size = std::fs::metadata(RunDir::new(&whole).checkpoint())
        .unwrap()
        .len();
    let limit = final_size * 13 / 10;

    let run = tmp.path().join("full");
    let mut command = train_command(&data, &run);
    #[allow(unsafe_code)] // The test's own process limit, set in the child before exec.
    // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        command.pre_exec(move || {
            let limit = libc::rlimit {
                rlim_cur: limit,
                rlim_max: limit,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let err = failure(&command.output().unwrap());
    assert!(
        err.contains("checkpoint.safetensors") && err.contains("bytes"),
        "{err}"
    );
    // The previous checkpoint is intact and short of the end; no temporary file is left.
    let saved = Checkpoint::load(&RunDir::new(&run).checkpoint(), &Device::Cpu).unwrap();
    assert!(saved.state.scale >= 2, "{:?}", saved.state);
    let leftovers: Vec<_> = std::fs::read_dir(&run)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    // With room again, --resume ends where the uninterrupted run ended.
    ok(&train_command(&data, &run).output().unwrap());
    assert_eq!(checkpoint_bits(&run), checkpoint_bits(&whole));
}
