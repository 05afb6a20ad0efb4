//! The files other tools read, read by them: the TUM trajectories by `evo_ape` (pip `evo`), the
//! maps by ROS map_server's documented rule, written here
//! apart from the crate's reader (map_server and nav2_map_server, `loadMapFromFile`): occupancy
//! `p = (255 - v) / 255` (`v / 255` with `negate`); in trinary mode (the default) `p >
//! occupied_thresh` is 100, `p < free_thresh` is 0, anything else -1 (unknown); in scale mode
//! only a transparent pixel is unknown.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use stereotag::sonar::grid::{GridGeometry, OccupancyMap};

/// The office demo's output (`--no-rerun`) with a localisation of its run against it in `loc`,
/// made once for the tests of this file (which run as one process).
fn demo() -> &'static Path {
    static OUT: OnceLock<PathBuf> = OnceLock::new();
    OUT.get_or_init(|| {
        // In the target directory, replaced on each run: a static is never dropped, so a
        // temporary directory would be left behind.
        let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("standard_files_demo");
        if out.exists() {
            std::fs::remove_dir_all(&out).unwrap();
        }
        let stereotag = |args: &[&str]| {
            let run = Command::new(env!("CARGO_BIN_EXE_stereotag"))
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .args(args)
                .output()
                .unwrap();
            assert!(
                run.status.success(),
                "{}",
                String::from_utf8_lossy(&run.stderr)
            );
        };
        let o = out.to_str().unwrap();
        stereotag(&["demo", "-q", "--no-rerun", "--out", o]);
        let run = out.join("run");
        let loc = out.join("loc");
        stereotag(&[
            "localize",
            "-q",
            "--no-rerun",
            "--survey",
            o,
            "--run",
            run.to_str().unwrap(),
            "--out",
            loc.to_str().unwrap(),
        ]);
        out
    })
}

/// `evo_ape tum REFERENCE ESTIMATE` (no alignment): the RMSE it prints, metres.
fn evo_ape_rmse(reference: &Path, estimate: &Path) -> f64 {
    let evo = std::env::var("EVO_APE").unwrap_or_else(|_| "evo_ape".into());
    let out = Command::new(&evo)
        .args(["tum", "--no_warnings"])
        .arg(reference)
        .arg(estimate)
        .output()
        .unwrap_or_else(|e| panic!("{evo}: {e} (pip install evo)"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text.lines()
        .find_map(|l| l.trim().strip_prefix("rmse"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no rmse in evo_ape's output:\n{text}"))
}

fn metric(report: &Path, key: &str) -> f64 {
    let report: Value = serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    report["metrics"][key]
        .as_f64()
        .unwrap_or_else(|| panic!("report.json has no metric {key}"))
}

#[test]
fn evo_reproduces_the_reports_trajectory_errors_from_the_tum_files() {
    let out = demo();
    for (name, key) in [
        ("odometry", "ate_m.odometry"),
        ("online", "ate_m.online"),
        ("offline", "ate_m.offline"),
    ] {
        let rmse = evo_ape_rmse(
            &out.join("trajectory_ground_truth.tum"),
            &out.join(format!("trajectory_{name}.tum")),
        );
        let ours = metric(&out.join("report.json"), key);
        assert!(
            (rmse - ours).abs() < 1e-3,
            "{name}: evo {rmse} m, report {ours} m"
        );
    }
    let loc = out.join("loc");
    let rmse = evo_ape_rmse(&loc.join("ground_truth.tum"), &loc.join("localized.tum"));
    let ours = metric(&loc.join("report.json"), "ate_m.localized");
    assert!(
        (rmse - ours).abs() < 1e-3,
        "localized: evo {rmse} m, report {ours} m"
    );
    for f in ["odometry.tum", "odometry_calibrated.tum"] {
        assert!(loc.join(f).exists(), "{f} missing");
    }
}

/// map_server's reading of `stem.yaml` + `stem.pgm` in `dir`, row 0 at the bottom as the grid's.
fn map_server(dir: &Path, stem: &str) -> (Vec<i8>, usize, usize) {
    let yaml: serde_yaml_ng::Value = serde_yaml_ng::from_str(
        &std::fs::read_to_string(dir.join(format!("{stem}.yaml"))).unwrap(),
    )
    .unwrap();
    let mode = yaml["mode"].as_str().unwrap_or("trinary");
    assert_eq!(
        mode, "trinary",
        "a PGM has no transparency: only trinary keeps unknown"
    );
    let occupied = yaml["occupied_thresh"].as_f64().unwrap();
    let free = yaml["free_thresh"].as_f64().unwrap();
    let negate = yaml["negate"].as_i64().unwrap() != 0;
    let img = image::open(dir.join(yaml["image"].as_str().unwrap()))
        .unwrap()
        .to_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut cells = vec![0i8; w * h];
    for (x, y, p) in img.enumerate_pixels() {
        let v = p.0[0] as f64;
        let occ = if negate {
            v / 255.0
        } else {
            (255.0 - v) / 255.0
        };
        cells[(h - 1 - y as usize) * w + x as usize] = if occ > occupied {
            100
        } else if occ < free {
            0
        } else {
            -1
        };
    }
    (cells, w, h)
}

#[test]
fn map_server_reads_every_unobserved_cell_as_unknown_and_keeps_the_classes() {
    // Every occupancy from 0 to 1 in small steps, the thresholds' neighbours, and unknown cells.
    let mut values: Vec<Option<f64>> = (0..=1000).map(|i| Some(i as f64 / 1000.0)).collect();
    for t in [0.2f64, 0.5] {
        for d in [-1e-9, -1e-4, 0.0, 1e-4, 1e-9] {
            values.push(Some(t + d));
        }
    }
    values.extend(std::iter::repeat_n(None, 300));
    let width = 40;
    values.resize(width * values.len().div_ceil(width), None);
    let map = OccupancyMap {
        geometry: GridGeometry {
            width,
            height: values.len() / width,
            resolution_m: 0.2,
            origin_m: [-3.0, -2.0],
        },
        occupancy: values,
        occupied_threshold: 0.5,
        free_threshold: 0.2,
    };
    let dir = tempfile::tempdir().unwrap();
    stereotag::io::save_ros_map(dir.path(), "map", &map).unwrap();
    let (cells, w, h) = map_server(dir.path(), "map");
    assert_eq!((w, h), (map.geometry.width, map.geometry.height));
    for (i, (&ros, ours)) in cells.iter().zip(&map.occupancy).enumerate() {
        let expected = match ours {
            None => -1,
            Some(_) if map.is_occupied(i) => 100,
            Some(_) if map.is_free(i) => 0,
            Some(_) => -1,
        };
        assert_eq!(ros, expected, "cell {i} ({ours:?})");
    }
    // The crate reads it back by the same rule.
    let back = stereotag::io::load_ros_occupancy(&dir.path().join("map.yaml")).unwrap();
    for (i, &ros) in cells.iter().enumerate() {
        let read = match back.occupancy[i] {
            None => -1,
            Some(_) if back.is_occupied(i) => 100,
            Some(_) if back.is_free(i) => 0,
            Some(_) => -1,
        };
        assert_eq!(read, ros, "cell {i} read back");
    }
}

#[test]
fn the_demo_maps_leave_unobserved_cells_unknown_to_map_server() {
    let out = demo();
    for stem in ["map", "map_online", "map_corrected"] {
        let (cells, _, _) = map_server(out, stem);
        let unknown = cells.iter().filter(|&&c| c == -1).count();
        let free = cells.iter().filter(|&&c| c == 0).count();
        // The office is 8 x 6 m in a 16 x 16 m grid: most of the grid is never observed.
        assert!(
            unknown > cells.len() / 3 && free > 0,
            "{stem}: {unknown} unknown, {free} free of {}",
            cells.len()
        );
    }
}
