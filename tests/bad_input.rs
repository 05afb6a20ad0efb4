//! Bad input gets a clear error naming the file and line, exit status 2, and writes nothing.

mod common;

use std::path::Path;
use std::process::Command;

fn stereotag(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A small valid run in `dir`.
fn good_run(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(
        dir.join("run.yaml"),
        "format: stereotag-run/1\nrobot:\n  sonar:\n    name: two\n    sensors:\n      - {x_m: 0.2, y_m: 0.0, bearing_rad: 0.0}\n      - {x_m: 0.0, y_m: 0.2, bearing_rad: 1.5708}\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("odometry.csv"),
        "t_s,x_m,y_m,theta_rad\n0,2.5,2.5,0\n1,2.6,2.5,0\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("sonar.csv"),
        "t_s,sensor,range_m\n0,0,1.0\n0,1,\n1,0,0.9\n1,1,1.2\n",
    )
    .unwrap();
}

/// Maps a good run with one file replaced by `content`: the temporary directory (run and map in
/// it), the map's path, the exit status and stderr.
fn map_with(file: &str, content: &str) -> (tempfile::TempDir, std::path::PathBuf, i32, String) {
    map_with_files(&[(file, content)])
}

/// [`map_with`] with several files replaced.
fn map_with_files(files: &[(&str, &str)]) -> (tempfile::TempDir, std::path::PathBuf, i32, String) {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    good_run(&run);
    for (file, content) in files {
        std::fs::write(run.join(file), content).unwrap();
    }
    let out = tmp.path().join("map");
    let (code, err) = stereotag(&[
        "map",
        "--run",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    (tmp, out, code, err)
}

/// Replaces one file of a good run and checks the error.
fn check(file: &str, content: &str, expect: &str) {
    let (tmp, out, code, err) = map_with(file, content);
    assert_eq!(code, 2, "{file}: {err}");
    assert!(
        err.contains(file) && err.contains(expect),
        "{file}: expected `{expect}` in: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.exists(), "nothing may be written");
    let leftovers: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty(), "no staging directory left behind");
}

#[test]
fn a_good_run_maps() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    good_run(&run);
    let out = tmp.path().join("map");
    let (code, err) = stereotag(&[
        "-q",
        "map",
        "--run",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    for f in [
        "map.pgm",
        "map.yaml",
        "map.png",
        "hough.png",
        "corners.csv",
        "report.json",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    // An existing output is kept without --force ...
    let (code, err) = stereotag(&[
        "map",
        "--run",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("--force"), "{err}");
    // ... and replaced with it.
    let (code, _) = stereotag(&[
        "-q",
        "map",
        "--run",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--force",
    ]);
    assert_eq!(code, 0);
}

/// Maps a good run whose odometry.csv is `odometry`; the run must still map (exit 0, a map
/// written); returns stderr.
fn map_warnings(odometry: &str) -> String {
    let (_tmp, out, code, err) = map_with("odometry.csv", odometry);
    assert_eq!(code, 0, "{err}");
    assert!(out.join("map.pgm").exists());
    err
}

#[test]
fn an_odometry_jump_is_named_with_its_line_and_the_run_still_maps() {
    let err = map_warnings("t_s,x_m,y_m,theta_rad\n0,2.5,2.5,0\n\n1,100002.6,2.5,0\n");
    assert!(
        err.contains("odometry.csv:4") && err.contains("jumps 100000.10 m"),
        "{err}"
    );
}

#[test]
fn a_run_the_grid_does_not_cover_is_warned_about() {
    // Odometry from a robot whose log starts at (-10, -10), run.yaml setting the paper's grid
    // (from (0, 0)).
    let yaml = "format: stereotag-run/1\nrobot:\n  sonar:\n    name: two\n    sensors:\n      - {x_m: 0.2, y_m: 0.0, bearing_rad: 0.0}\n      - {x_m: 0.0, y_m: 0.2, bearing_rad: 1.5708}\nmapping:\n  grid:\n    origin_m: [0.0, 0.0]\n";
    let (_tmp, _out, code, err) = map_with_files(&[
        ("run.yaml", yaml),
        (
            "odometry.csv",
            "t_s,x_m,y_m,theta_rad\n0,-10,-10,0\n1,-9.9,-10,0\n",
        ),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("3 of 3 sonar echoes (100%) fall outside the grid (x 0.0..16.0 m"),
        "{err}"
    );
}

#[test]
fn a_run_yaml_without_a_grid_gets_one_fitted_to_the_run() {
    // The same robot, run.yaml silent: the grid is fitted and every echo falls on it.
    let err = map_warnings("t_s,x_m,y_m,theta_rad\n0,-10,-10,0\n1,-9.9,-10,0\n");
    assert!(err.contains("run.yaml sets no grid"), "{err}");
    assert!(!err.contains("outside the grid"), "{err}");
}

#[test]
fn truncated_row() {
    check(
        "sonar.csv",
        "t_s,sensor,range_m\n0,0,1.0\n0,1\n",
        "sonar.csv:3",
    );
}

#[test]
fn not_a_number() {
    check(
        "odometry.csv",
        "t_s,x_m,y_m,theta_rad\n0,2.5,abc,0\n",
        "odometry.csv:2",
    );
}

#[test]
fn nan_and_infinity() {
    check(
        "odometry.csv",
        "t_s,x_m,y_m,theta_rad\n0,2.5,NaN,0\n",
        "finite",
    );
    check("sonar.csv", "t_s,sensor,range_m\n0,0,inf\n", "sonar.csv:2");
}

#[test]
fn negative_range() {
    check(
        "sonar.csv",
        "t_s,sensor,range_m\n0,0,-0.5\n",
        "sonar.csv:2: range_m is -0.5",
    );
}

#[test]
fn unknown_sensor() {
    check(
        "sonar.csv",
        "t_s,sensor,range_m\n0,7,1.0\n",
        "unknown sensor 7",
    );
}

#[test]
fn time_going_backwards() {
    check(
        "odometry.csv",
        "t_s,x_m,y_m,theta_rad\n3,2.5,2.5,0\n0.5,2.5,2.5,0\n",
        "odometry.csv:3: time 0.5 s goes backwards by 2.500 s",
    );
}

#[test]
fn rows_a_little_out_of_order_are_reordered_with_one_warning() {
    let (tmp, out, code, err) = map_with(
        "sonar.csv",
        "t_s,sensor,range_m\n0,0,1.0\n0.4,1,\n0.3,0,0.9\n1,1,1.2\n0.8,0,1.1\n",
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.join("map.yaml").exists());
    assert!(
        err.contains(
            "sonar.csv: 2 rows out of time order by up to 0.200 s (the first at line 4) re-ordered"
        ),
        "{err}"
    );
    assert_eq!(err.matches("out of time order").count(), 1, "{err}");
    // report.json keeps the warning, once, with the map's own.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let warnings = report["warnings"].to_string();
    assert_eq!(
        warnings.matches("out of time order").count(),
        1,
        "{warnings}"
    );
    // Re-ordered, the rows are read in time order.
    let run = stereotag::io::load_run(&tmp.path().join("run")).unwrap();
    let times: Vec<f64> = run.sonar.iter().map(|r| r.t_s).collect();
    assert_eq!(times, [0.0, 0.3, 0.4, 0.8, 1.0]);
}

#[test]
fn wrong_header() {
    check(
        "sonar.csv",
        "time,sensor,range\n0,0,1.0\n",
        "sonar.csv:1: expected the header",
    );
}

#[test]
fn yaml_key_of_the_wrong_type() {
    check(
        "run.yaml",
        "format: stereotag-run/1\nrobot:\n  sonar:\n    name: two\n    max_range_m: far\n    sensors: []\n",
        "run.yaml:5",
    );
}

#[test]
fn yaml_unknown_key() {
    check(
        "run.yaml",
        "format: stereotag-run/1\ncolour: red\nrobot:\n  sonar: {name: a, sensors: []}\n",
        "unknown field `colour`",
    );
}

#[test]
fn mapping_settings_out_of_range_name_the_file_and_key() {
    // A setting the sampling would later loosen is checked as given.
    for (walls, expect) in [
        ("{min_readings: 1}", "walls.min_readings"),
        ("{max_gap_m: -1}", "walls.max_gap_m"),
    ] {
        check(
            "run.yaml",
            &format!("format: stereotag-run/1\nrobot:\n  sonar: {{name: a, sensors: [{{x_m: 0, y_m: 0, bearing_rad: 0}}]}}\nmapping:\n  walls: {walls}\n"),
            expect,
        );
    }
    check(
        "run.yaml",
        "format: stereotag-run/1\nrobot:\n  sonar: {name: a, sensors: [{x_m: 0, y_m: 0, bearing_rad: 0}]}\nmapping:\n  grid: {resolution_m: 0}\n",
        "grid.resolution_m",
    );
}

#[test]
fn a_shortest_range_past_the_longest_is_refused() {
    check(
        "run.yaml",
        "format: stereotag-run/1\nrobot:\n  sonar: {name: a, max_range_m: 2.1, min_range_m: 3.0, sensors: [{x_m: 0, y_m: 0, bearing_rad: 0}]}\n",
        "min_range_m (if given) from 0 up to max_range_m",
    );
}

#[test]
fn run_from_another_version() {
    check("run.yaml", "format: stereotag-run/0\nrobot:\n  sonar: {name: a, sensors: [{x_m: 0, y_m: 0, bearing_rad: 0}]}\n", "this stereotag reads");
}

#[test]
fn world_with_bad_wall_and_missing_file() {
    let tmp = tempfile::tempdir().unwrap();
    let world = tmp.path().join("w.yaml");
    std::fs::write(
        &world,
        "start: {x_m: 1, y_m: 1}\nwalls:\n  - polyline_m: [[0, 0]]\n",
    )
    .unwrap();
    let out = tmp.path().join("run");
    let (code, err) = stereotag(&[
        "simulate",
        "--world",
        world.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(
        err.contains("w.yaml") && err.contains("walls[0].polyline_m"),
        "{err}"
    );
    assert!(!out.exists());
    let (code, err) = stereotag(&[
        "simulate",
        "--world",
        "/nonexistent/world.yaml",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("/nonexistent/world.yaml"), "{err}");
}

#[test]
fn start_inside_a_wall() {
    let tmp = tempfile::tempdir().unwrap();
    let world = tmp.path().join("w.yaml");
    std::fs::write(&world, "start: {x_m: 0.05, y_m: 1}\nwalls:\n  - {polyline_m: [[0, 0], [4, 0], [4, 3], [0, 3]], closed: true}\n").unwrap();
    let (code, err) = stereotag(&[
        "simulate",
        "--world",
        world.to_str().unwrap(),
        "--out",
        tmp.path().join("r").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("start pose"), "{err}");
}

#[test]
fn detect_names_a_missing_or_corrupt_image() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = tmp.path().join("bad.png");
    std::fs::write(&bad, b"not a png").unwrap();
    for (path, expect) in [
        (bad.to_str().unwrap(), "cannot decode"),
        ("/nonexistent/left.png", "No such file"),
    ] {
        let (code, err) = stereotag(&["detect", path]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(path) && err.contains(expect), "{err}");
    }
    let (code, err) = stereotag(&["detect", "--family", "tag99", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("tag36h11"), "{err}");
}

#[test]
fn detect_prints_the_design_json() {
    let Some(photo) = common::shared("apriltag_test/34139872896_defdb2f8d9_c.jpg") else {
        return;
    };
    let out = Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .args(["detect", "--decimate", "1", photo.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let dets = v["detections"].as_array().unwrap();
    assert!(dets.len() >= 10, "{}", dets.len());
    for d in dets {
        assert_eq!(d["family"], "tag36h11");
        assert_eq!(d["corners_px"].as_array().unwrap().len(), 4);
        assert!(d["centre_px"][0].is_f64() && d["hamming"].is_u64() && d["id"].is_u64());
    }
}

#[test]
fn a_fractional_decimation_is_the_c_librarys_alone() {
    let Some(photo) = common::shared("apriltag_test/34139872896_defdb2f8d9_c.jpg") else {
        return;
    };
    let photo = photo.to_str().unwrap();
    let (code, err) = stereotag(&["detect", "--decimate", "0.5", photo]);
    assert_eq!(code, 2);
    assert!(err.contains("--decimate 0.5: must be at least 1"), "{err}");
    let (code, err) = stereotag(&["detect", "--backend", "kornia", "--decimate", "1.5", photo]);
    assert_eq!(code, 2);
    assert!(err.contains("whole factors"), "{err}");
    // The C library at 1.5 finds most of the photo's tags (8 of the 10 at full resolution).
    let out = Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .args(["detect", "--decimate", "1.5", photo])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["detections"].as_array().unwrap().len() >= 8);
}

#[test]
fn the_demo_refuses_a_bad_decimation_before_simulating() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let (code, err) = stereotag(&[
        "demo",
        "--decimate",
        "0.5",
        "--no-rerun",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--decimate 0.5: must be at least 1"), "{err}");
    assert!(!out.exists());
}

#[test]
fn stereo_detect_checks_the_rig_against_the_images() {
    let Some(photo) = common::shared("apriltag_test/34139872896_defdb2f8d9_c.jpg") else {
        return;
    };
    let rig = common::root().join("calibration/rigs/default.yaml");
    let p = photo.to_str().unwrap();
    let (code, err) = stereotag(&["detect", "--rig", rig.to_str().unwrap(), p, p]);
    assert_eq!(code, 2);
    assert!(
        err.contains("799x533") && err.contains("640x480") && err.contains(p),
        "{err}"
    );
    let (code, err) = stereotag(&["detect", "--rig", rig.to_str().unwrap(), p]);
    assert_eq!(code, 2);
    assert!(err.contains("exactly two images"), "{err}");
}

#[test]
fn render_pose_must_be_three_finite_numbers_and_sequences_render() {
    let tmp = tempfile::tempdir().unwrap();
    let world = common::sample("office/world.yaml");
    let rig = common::root().join("calibration/rigs/default.yaml");
    let out = tmp.path().join("pair");
    let base = [
        "render",
        "--world",
        world.to_str().unwrap(),
        "--rig",
        rig.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    for bad in ["1,2", "1,2,x", "1,2,inf"] {
        let (code, err) = stereotag(&[&base[..], &["--pose", bad]].concat());
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(err.contains("--pose"), "{err}");
        assert!(!out.exists());
    }
    let poses = tmp.path().join("poses.csv");
    std::fs::write(
        &poses,
        "t_s,x_m,y_m,theta_rad\n0,1.0,6.3,2.35\n1,1.2,6.0,2.2\n",
    )
    .unwrap();
    let (code, err) = stereotag(&[&base[..], &["-q", "--poses", poses.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["frames"].as_array().unwrap().len(), 2);
    assert!(out.join("left/000001.png").exists() && out.join("right/000001.png").exists());
}

/// A good run with one stereo pair written from a rendered office pair.
fn run_with_pair(dir: &Path) {
    good_run(dir);
    let pair = dir.join("pair");
    let (code, err) = stereotag(&[
        "render",
        "--world",
        &common::sample("office/world.yaml").to_string_lossy(),
        "--pose",
        "1.0,6.3,2.35",
        "--out",
        pair.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    std::fs::create_dir_all(dir.join("stereo")).unwrap();
    std::fs::rename(pair.join("left.png"), dir.join("stereo/l.png")).unwrap();
    std::fs::rename(pair.join("right.png"), dir.join("stereo/r.png")).unwrap();
    std::fs::remove_dir_all(&pair).unwrap();
    std::fs::write(
        dir.join("stereo.csv"),
        "t_s,left,right\n0.5,stereo/l.png,stereo/r.png\n",
    )
    .unwrap();
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/default.yaml"),
        dir.join("rig.yaml"),
    )
    .unwrap();
    let yaml = std::fs::read_to_string(dir.join("run.yaml")).unwrap();
    std::fs::write(
        dir.join("run.yaml"),
        yaml.replace("robot:\n", "robot:\n  rig: rig.yaml\n"),
    )
    .unwrap();
}

fn survey(run: &Path, out: &Path) -> (i32, String) {
    survey_with(run, out, &[])
}

fn survey_with(run: &Path, out: &Path, extra: &[&str]) -> (i32, String) {
    let mut args = vec![
        "survey",
        "--run",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--no-rerun",
    ];
    args.extend_from_slice(extra);
    stereotag(&args)
}

#[test]
fn survey_of_a_sonar_only_run_says_so_and_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    good_run(&run);
    let out = tmp.path().join("survey");
    let (code, err) = survey(&run, &out);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("no stereo pairs"), "{err}");
    assert!(out.join("landmarks.json").exists());
}

#[test]
fn survey_names_an_earlier_survey_it_cannot_take_a_calibration_from() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    good_run(&run);
    let earlier = tmp.path().join("earlier");
    std::fs::create_dir_all(&earlier).unwrap();
    let with = |out: &Path| {
        survey_with(
            &run,
            out,
            &["--calibration-from", earlier.to_str().unwrap()],
        )
    };
    // No landmarks.json there.
    let out = tmp.path().join("none");
    let (code, err) = with(&out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("landmarks.json"), "{err}");
    assert!(!out.exists());
    // A landmarks.json without an odometry calibration.
    std::fs::write(earlier.join("landmarks.json"), r#"{"landmarks": []}"#).unwrap();
    let out = tmp.path().join("no_calibration");
    let (code, err) = with(&out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no odometry_calibration"), "{err}");
    assert!(!out.exists());
}

#[test]
fn survey_names_a_missing_image_and_a_rig_that_does_not_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    run_with_pair(&run);
    // The pair surveys, with the C library (decimating by 1.5 by default) and with kornia,
    // whose default is 1: it decimates by whole factors only.
    let (code, err) = survey(&run, &tmp.path().join("ok"));
    assert_eq!(code, 0, "{err}");
    let (code, err) = survey_with(&run, &tmp.path().join("kornia"), &["--backend", "kornia"]);
    assert_eq!(code, 0, "{err}");
    let (code, err) = survey_with(
        &run,
        &tmp.path().join("kornia_1.5"),
        &["--backend", "kornia", "--decimate", "1.5"],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("whole factors"), "{err}");
    assert!(!tmp.path().join("kornia_1.5").exists());

    std::fs::remove_file(run.join("stereo/r.png")).unwrap();
    let out = tmp.path().join("missing");
    let (code, err) = survey(&run, &out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("r.png"), "{err}");
    assert!(!out.exists());

    run_with_pair(&run);
    let rig = std::fs::read_to_string(run.join("rig.yaml")).unwrap();
    std::fs::write(
        run.join("rig.yaml"),
        rig.replace("[640, 480]", "[752, 480]"),
    )
    .unwrap();
    let out = tmp.path().join("rig");
    let (code, err) = survey(&run, &out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("l.png") && err.contains("640x480"), "{err}");
    assert!(!out.exists());
}

#[test]
fn localize_names_a_bad_landmarks_file() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    good_run(&run);
    let survey_dir = tmp.path().join("survey");
    std::fs::create_dir_all(&survey_dir).unwrap();
    let out = tmp.path().join("loc");
    let localize_with = |extra: &[&str]| {
        let mut args = vec![
            "localize",
            "--survey",
            survey_dir.to_str().unwrap(),
            "--run",
            run.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        stereotag(&args)
    };
    let localize = || localize_with(&[]);
    for (landmarks, says) in [
        (
            "{\"landmarks\": [{\"id\": 1, \"family\": \"tag36h11\"}]}",
            "size_m",
        ),
        // An odometry calibration no robot has.
        (
            "{\"landmarks\": [], \"odometry_calibration\": {\"turn_scale_error\": 3.0, \
             \"heading_drift_rad_per_m\": 0.0, \"distance_scale_error\": 0.0}}",
            "odometry_calibration.turn_scale_error",
        ),
        // An odometry noise no robot has (a hundred times the model's).
        (
            "{\"landmarks\": [], \"odometry_calibration\": {\"turn_scale_error\": 0.01, \
             \"heading_drift_rad_per_m\": 0.0, \"distance_scale_error\": 0.0}, \
             \"odometry_noise_scale\": {\"translation\": 0.3, \"turning\": 100.0, \"drift\": 0.7}}",
            "odometry_noise_scale.turning",
        ),
    ] {
        std::fs::write(survey_dir.join("landmarks.json"), landmarks).unwrap();
        let (code, err) = localize();
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains("landmarks.json") && err.contains(says),
            "{err}"
        );
        assert!(!out.exists());
    }
    // A good landmarks file, a survey wall with a broken number on line 3.
    std::fs::write(survey_dir.join("landmarks.json"), "{\"landmarks\": []}").unwrap();
    std::fs::write(
        survey_dir.join("walls_corrected.csv"),
        "normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m\n\
         0,1,1,0,1,2,20,0.01\n\
         0,1,1,0,1,two,20,0.01\n",
    )
    .unwrap();
    let (code, err) = localize();
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("walls_corrected.csv") && err.contains('3') && err.contains("to_y_m"),
        "{err}"
    );
    assert!(!out.exists());
    // Good walls with their sigma, and their covariance naming a face that is not there (line 3)
    // or a variance that is not positive (line 2).
    std::fs::write(
        survey_dir.join("walls_corrected.csv"),
        "normal_rad,offset_m,from_x_m,from_y_m,to_x_m,to_y_m,readings,rms_m,sigma_m\n\
         0,1,1,0,1,2,20,0.01,0.005\n",
    )
    .unwrap();
    for (covariance, line, says) in [
        (
            "0,offset,0,offset,2.5e-5\n0,offset,1,offset,1e-6\n",
            '3',
            "face 1",
        ),
        ("0,turn,0,turn,-1e-6\n", '2', "not positive"),
    ] {
        std::fs::write(
            survey_dir.join("walls_corrected_covariance.csv"),
            format!("wall_a,part_a,wall_b,part_b,covariance\n{covariance}"),
        )
        .unwrap();
        let (code, err) = localize();
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains("walls_corrected_covariance.csv")
                && err.contains(line)
                && err.contains(says),
            "{err}"
        );
        assert!(!out.exists());
    }
    std::fs::remove_file(survey_dir.join("walls_corrected_covariance.csv")).unwrap();
    // Fusion settings out of range: named with the file and the key.
    std::fs::remove_file(survey_dir.join("walls_corrected.csv")).unwrap();
    let config = tmp.path().join("fuse.yaml");
    std::fs::write(&config, "sonar_sigma_m: -0.01\n").unwrap();
    let (code, err) = localize_with(&["--config", config.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("fuse.yaml") && err.contains("sonar_sigma_m"),
        "{err}"
    );
    assert!(!out.exists());
}

/// `stereotag calibrate` with image globs; returns the exit code and stderr, checks nothing was
/// written.
fn calibrate_images(target: &str, left: &str, right: &str) -> (i32, String) {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cal");
    let root = common::root();
    let (code, err) = stereotag(&[
        "calibrate",
        "--target",
        target,
        "--left",
        root.join(left).to_str().unwrap(),
        "--right",
        root.join(right).to_str().unwrap(),
        "--no-rerun",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!out.exists(), "nothing may be written");
    assert!(!err.contains("panicked"), "{err}");
    (code, err)
}

#[test]
fn calibration_pairs_of_different_sizes_or_counts_are_refused() {
    let target = common::root().join("calibration/targets/checkerboard_9x6.yaml");
    let target = target.to_str().unwrap();
    let (code, err) = calibrate_images(
        target,
        "../shared/data/mrpt_stereo_calib/0_left.jpg",
        "../shared/data/aprilgrid_frames/EuRoC.png",
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("0_left.jpg is 1024x768 but") && err.contains("must be the same size"),
        "{err}"
    );
    let (code, err) = calibrate_images(
        target,
        "../shared/data/mrpt_stereo_calib/*_left.jpg",
        "../shared/data/mrpt_stereo_calib/0_right.jpg",
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("4 left images but 1 right images"), "{err}");
}

#[test]
fn calibration_target_with_a_missing_field_names_it() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("t.yaml");
    std::fs::write(
        &target,
        "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n",
    )
    .unwrap();
    let (code, err) = calibrate_images(
        target.to_str().unwrap(),
        "../shared/data/mrpt_stereo_calib/*_left.jpg",
        "../shared/data/mrpt_stereo_calib/*_right.jpg",
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("t.yaml") && err.contains("missing field `rowSpacingMeters`"),
        "{err}"
    );
}

#[test]
fn calibration_target_with_a_wrong_typed_or_unknown_key_names_the_line() {
    let tmp = tempfile::tempdir().unwrap();
    for (text, want) in [
        (
            "target_type: aprilgrid\ntagCols: six\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n",
            "t.yaml:2: column 10: tagCols: invalid type",
        ),
        (
            "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\ncolour: red\n",
            "t.yaml:6: column 1: unknown field `colour`",
        ),
        (
            "# a ring of circles\ntarget_type: circles\n",
            "t.yaml:2: target_type `circles`: expected `aprilgrid`, `checkerboard`, `tagboard`, `charuco` or `boards`",
        ),
        (
            "target_type: charuco\ndictionary: DICT_4X4_50\nsquaresX: 20\nsquaresY: 20\nsquareLength: 0.03\nmarkerLength: 0.02\n",
            "t.yaml: tag 50 is not in DICT_4X4_50 (it has 50 tags)",
        ),
        (
            "target_type: charuco\ndictionary: DICT_9X9_50\nsquaresX: 5\nsquaresY: 4\nsquareLength: 0.03\nmarkerLength: 0.02\n",
            "t.yaml:2: column 13: dictionary: unknown tag family \"DICT_9X9_50\"",
        ),
    ] {
        let target = tmp.path().join("t.yaml");
        std::fs::write(&target, text).unwrap();
        let (code, err) = calibrate_images(
            target.to_str().unwrap(),
            "../shared/data/mrpt_stereo_calib/*_left.jpg",
            "../shared/data/mrpt_stereo_calib/*_right.jpg",
        );
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(want), "{err}\nwanted: {want}");
        // The place is said once, at the front (the parser's " at line L column C" is cut).
        assert!(!err.contains(" at line "), "{err}");
    }
}

/// The default rig with its `stereotag:` section replaced by `mounting` (none when empty).
fn rig_with_mounting(dir: &Path, mounting: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join(stereotag::io::DEFAULT_RIG),
    )
    .unwrap();
    let cut = text
        .find("\nstereotag:")
        .expect("the default rig has a stereotag section");
    let path = dir.join("rig.yaml");
    std::fs::write(&path, format!("{}\n{mounting}", &text[..cut])).unwrap();
    path
}

#[test]
fn a_rig_that_does_not_say_where_it_sits_stops_simulate_with_how_to_say_it() {
    let identity = "stereotag:\n  robot_from_left:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n";
    for (mounting, says) in [("", "says nowhere"), (identity, "is the identity")] {
        let tmp = tempfile::tempdir().unwrap();
        let rig = rig_with_mounting(tmp.path(), mounting);
        let out = tmp.path().join("run");
        let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/office/world.yaml");
        let (code, err) = stereotag(&[
            "simulate",
            "--world",
            world.to_str().unwrap(),
            "--rig",
            rig.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, 2, "{err}");
        for words in [
            "rig.yaml",
            says,
            "robot_from_left",
            "run.yaml",
            "--default-mounting",
        ] {
            assert!(err.contains(words), "expected {words:?} in: {err}");
        }
        assert!(!out.exists(), "nothing may be written");
    }
}
