//! The maps we write, read as ROS map_server reads them: its documented rule, written here
//! apart from the crate's reader (map_server and nav2_map_server, `loadMapFromFile`): occupancy
//! `p = (255 - v) / 255` (`v / 255` with `negate`); in trinary mode (the default) `p >
//! occupied_thresh` is 100, `p < free_thresh` is 0, anything else -1 (unknown); in scale mode
//! only a transparent pixel is unknown.

use stereotag::sonar::grid::{GridGeometry, OccupancyMap};

/// map_server's reading of `stem.yaml` + `stem.pgm` in `dir`, row 0 at the bottom as the grid's.
fn map_server(dir: &std::path::Path, stem: &str) -> (Vec<i8>, usize, usize) {
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
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["demo", "-q", "--no-rerun", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for stem in ["map", "map_online", "map_corrected"] {
        let (cells, _, _) = map_server(&out, stem);
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
