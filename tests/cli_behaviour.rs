//! The command line as a Unix tool: it runs from any directory (the samples, targets and rigs
//! built in), is quiet when asked, stops cleanly on a closed pipe, writes no colour codes into
//! pipes, and an interrupted command leaves nothing behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// An empty scratch directory outside the repository.
fn empty_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("stereotag-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The binary, run in `dir`.
fn stereotag_in(dir: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_stereotag"));
    c.current_dir(dir).env_remove("RUST_LOG");
    c
}

/// Names in `dir` of the hidden staging directories of unfinished outputs.
fn partial_outputs(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".partial-"))
        .collect()
}

#[test]
fn the_demo_runs_in_an_empty_directory_and_quiet_means_quiet() {
    let dir = empty_dir("demo");
    let out = stereotag_in(&dir).args(["demo", "-q"]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.stdout.is_empty(), "-q printed a summary");
    assert!(out.stderr.is_empty(), "-q printed to stderr");
    for file in [
        "landmarks.json",
        "survey.rrd",
        "map_corrected.png",
        "run/run.yaml",
    ] {
        assert!(dir.join("out").join(file).is_file(), "no out/{file}");
    }
    // The run names the bundled rig; it and the world are read from the built-in copies.
    assert!(!dir.join("samples").exists() && !dir.join("calibration").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_built_in_files_can_be_written_out_and_are_then_read_from_disk() {
    let dir = empty_dir("samples");
    let out = stereotag_in(&dir).args(["samples"]).output().unwrap();
    assert!(out.status.success());
    assert!(dir.join("samples/office/world.yaml").is_file());
    assert!(dir.join("calibration/targets/aprilgrid_6x6.yaml").is_file());
    // An edited copy on disk wins over the built-in one.
    std::fs::write(dir.join("calibration/rigs/default.yaml"), "not: [a rig").unwrap();
    let out = stereotag_in(&dir)
        .args(["rig", "calibration/rigs/default.yaml", "--out", "x"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("calibration/rigs/default.yaml:1"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_interrupted_command_removes_its_unfinished_output() {
    let dir = empty_dir("interrupt");
    let child = stereotag_in(&dir)
        .args(["demo", "--no-rerun"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Interrupted once the output is being written (the run's pictures go in first).
    let start = Instant::now();
    while partial_outputs(&dir).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no output started"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(1500));
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "exit status after Ctrl-C");
    assert!(String::from_utf8_lossy(&out.stderr).contains("interrupted"));
    assert_eq!(partial_outputs(&dir), Vec::<String>::new());
    assert!(!dir.join("out").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_interrupted_recording_saved_elsewhere_is_removed_and_an_old_one_kept() {
    let dir = empty_dir("interrupt_save");
    let side = dir.join("side");
    std::fs::create_dir_all(&side).unwrap();
    std::fs::write(side.join("d.rrd"), b"an earlier recording").unwrap();
    let child = stereotag_in(&dir)
        .args(["demo", "-q", "--save", "side/d.rrd"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while partial_outputs(&side).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the recording never started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(partial_outputs(&side), Vec::<String>::new());
    assert_eq!(partial_outputs(&dir), Vec::<String>::new());
    assert_eq!(
        std::fs::read(side.join("d.rrd")).unwrap(),
        b"an earlier recording"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_reader_that_went_away_is_not_an_error() {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader); // every write to the pipe now fails with EPIPE
    let out = stereotag_in(Path::new(env!("CARGO_MANIFEST_DIR")))
        .args(["config", "--default", "fuse"])
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn logs_into_a_pipe_have_no_colour_codes() {
    let dir = empty_dir("colour");
    let out = stereotag_in(&dir)
        .args(["rig", "calibration/rigs/default.yaml", "--out", "rig"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("built into stereotag"), "{stderr}");
    assert!(!stderr.contains('\u{1b}'), "{stderr:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn settings_defaults_come_with_a_comment_per_setting_and_read_back() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for kind in ["mapping", "simulation", "fuse", "plan"] {
        let out = stereotag_in(root)
            .args(["config", "--default", kind])
            .output()
            .unwrap();
        assert!(out.status.success());
        let text = String::from_utf8(out.stdout).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        // Every key line (`name: value` or a nested `name:`) follows a comment line, but for the
        // fields of a list's items (the sonar transducers), documented once by the list.
        let mut item_indent: Option<usize> = None;
        for (i, line) in lines.iter().enumerate() {
            let trimmed = line.trim_start();
            let indent = line.len() - trimmed.len();
            if trimmed.starts_with("- ") {
                item_indent = Some(indent);
                continue;
            }
            if item_indent.is_some_and(|d| indent > d) {
                continue;
            }
            item_indent = None;
            if trimmed.starts_with('#') || !trimmed.contains(':') {
                continue;
            }
            assert!(
                i > 0 && lines[i - 1].trim_start().starts_with('#'),
                "{kind}: no comment above `{line}`"
            );
        }
        let back: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).unwrap();
        assert!(back.as_mapping().is_some_and(|m| !m.is_empty()), "{kind}");
    }
}
