//! A recorder killed with SIGKILL at 20 points of a live run leaves, each time, a file that the
//! official Python reader (`mcap` 1.6.0, `make_reader`), the official Rust reader (the `mcap`
//! crate's `MessageStream`) and ours read whole: no error, the same messages, and the raw
//! samples a run of consecutive sequence numbers from the first recorded (nothing missing
//! before the kill).

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::*;
use ipc_types::RawImuSample;
use recording::mcap::Reader;

/// Longest wait for a process or the first samples (a loaded machine is slow).
const WAIT: Duration = Duration::from_secs(30);

/// Messages the official Python reader reads from `path` (its seeking reader, as
/// `read_recording.py` uses it), iterating every one.
fn python_count(path: &Path) -> usize {
    let script = "import sys\nfrom mcap.reader import make_reader\n\
                  with open(sys.argv[1], 'rb') as f:\n    \
                  print(sum(1 for _ in make_reader(f).iter_messages(log_time_order=False)))";
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(path)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "the Python reader fails on {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .trim()
        .parse()
        .unwrap()
}

/// Messages the `mcap` crate reads from `path`, every one without error.
fn mcap_crate_count(path: &Path) -> usize {
    let bytes = std::fs::read(path).unwrap();
    let mut count = 0;
    for message in ::mcap::MessageStream::new(&bytes).unwrap() {
        message.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        count += 1;
    }
    count
}

/// Messages our reader reads from `path`, which must read whole (no truncation), and its raw
/// samples.
fn our_read(path: &Path) -> (usize, Vec<RawImuSample>) {
    let reader = Reader::open(path).unwrap();
    let (mut count, mut raw) = (0, Vec::new());
    for message in reader.messages().unwrap() {
        let message = message.unwrap_or_else(|e| panic!("{e}"));
        count += 1;
        if let Some(sample) = message.decode::<RawImuSample>() {
            raw.push(sample.unwrap());
        }
    }
    (count, raw)
}

/// Whether the recorder being written to `path` has put a raw sample in it yet: the file may
/// not exist, be empty or end in a record still being written (read up to there).
fn has_raw_sample(path: &Path) -> bool {
    let Ok(reader) = Reader::open(path) else {
        return false;
    };
    let Ok(messages) = reader.messages() else {
        return false;
    };
    messages
        .map_while(Result::ok)
        .any(|m| m.decode::<RawImuSample>().is_some())
}

#[test]
fn every_killed_recorders_file_reads_whole_in_every_reader() {
    let ns = namespace("killed");
    let csv = tmp("killed.csv");
    recording::csv::write_raw(&csv, &raw_samples(4000, 0, 1000), None).unwrap();
    // A live source for as long as the kills take: 4 s at 1 kHz, again and again.
    let replay = spawn(
        &mems_replay(),
        &[csv.to_str().unwrap(), "--loop", "--namespace", &ns],
    );
    // Kill points 0 to 1.2 s after the first samples reach the file, spread by a fixed
    // pseudo-random sequence (the test is the same on every run; where the kill lands in the
    // recorder's work depends on the machine anyway).
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    for k in 0..20 {
        let path = tmp(&format!("killed-{k}.mcap"));
        let recorder = spawn(
            &mems_record(),
            &["--out", path.to_str().unwrap(), "--namespace", &ns],
        );
        wait_until(WAIT, "the first samples in the file", || {
            has_raw_sample(&path)
        });
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        std::thread::sleep(Duration::from_millis(state % 1200));
        recorder.signal(libc::SIGKILL);
        let (status, _) = recorder.wait(WAIT);
        assert_eq!(
            std::os::unix::process::ExitStatusExt::signal(&status),
            Some(libc::SIGKILL)
        );

        let (ours, raw) = our_read(&path);
        let python = python_count(&path);
        let official = mcap_crate_count(&path);
        eprintln!("kill {k}: {ours} messages, {} raw samples", raw.len());
        assert!(!raw.is_empty(), "{}", path.display());
        assert_eq!(python, ours, "{}: Python against ours", path.display());
        assert_eq!(
            official,
            ours,
            "{}: mcap crate against ours",
            path.display()
        );
        // Consecutive sequence numbers, except where the looping replay starts over.
        for pair in raw.windows(2) {
            let (a, b) = (pair[0].seq, pair[1].seq);
            assert!(b == a + 1 || b == 0, "{}: seq {a} then {b}", path.display());
        }
        let mode = std::os::unix::fs::PermissionsExt::mode(
            &std::fs::metadata(&path).unwrap().permissions(),
        );
        assert_eq!(mode & 0o777, 0o600, "{} is private", path.display());
    }
    replay.signal(libc::SIGTERM);
    let (status, stdout) = replay.wait(WAIT);
    assert!(status.success(), "mems-replay failed: {stdout}");
}
