//! `stereotag import` of a simulated office run written as a ROS 2 bag by an independent writer
//! (the Python `rosbags` package, `scripts/run_to_bag.py`) and as an ASL folder: the imported run
//! must be the run it was written from, and survey as it does.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn stereotag(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_stereotag"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("RERUN_ANALYTICS", "off")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn ok(args: &[&str]) {
    let (code, err) = stereotag(args);
    assert_eq!(code, 0, "stereotag {}: {err}", args.join(" "));
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A simulated office run (600 s, with pictures), made once for the tests of this file.
fn office_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let run = dir.join("office");
        ok(&[
            "simulate",
            "--world",
            "samples/office/world.yaml",
            "--duration-s",
            "600",
            "--out",
            s(&run),
            "-q",
        ]);
        run
    })
}

/// `scripts/run_to_bag.py RUN OUT ARGS...`.
fn write_bag(run: &Path, out: &Path, args: &[&str]) {
    let status = Command::new("python3")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .arg("scripts/run_to_bag.py")
        .args([s(run), s(out)])
        .args(args)
        .status()
        .expect("python3 runs the bag writer");
    assert!(
        status.success(),
        "scripts/run_to_bag.py failed: it needs `pip install rosbags` (.ci/run installs it)"
    );
}

fn text(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn json(p: &Path) -> Value {
    serde_json::from_str(&text(p)).unwrap()
}

/// The numbers of a CSV file, row by row (header left out).
fn csv_numbers(p: &Path) -> Vec<Vec<f64>> {
    text(p)
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .map(|f| f.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect()
}

fn assert_csv_close(a: &Path, b: &Path, tol: f64) {
    let (x, y) = (csv_numbers(a), csv_numbers(b));
    assert_eq!(x.len(), y.len(), "{} vs {}", a.display(), b.display());
    for (i, (r, q)) in x.iter().zip(&y).enumerate() {
        for (u, v) in r.iter().zip(q) {
            assert!(
                (u - v).abs() <= tol || (u.is_nan() && v.is_nan()),
                "{} line {}: {r:?} vs {q:?}",
                b.display(),
                i + 2
            );
        }
    }
}

/// The run's mapping settings copied from `from` (the imported run fits its own grid; the
/// comparison needs the same one).
fn same_mapping(from: &Path, to: &Path) {
    let a: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text(&from.join("run.yaml"))).unwrap();
    let mut b: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text(&to.join("run.yaml"))).unwrap();
    b["mapping"] = a["mapping"].clone();
    std::fs::write(to.join("run.yaml"), serde_yaml_ng::to_string(&b).unwrap()).unwrap();
}

fn landmarks(survey: &Path) -> Vec<(u64, [f64; 2])> {
    let l = json(&survey.join("landmarks.json"));
    l["landmarks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| {
            let p = &l["position_m"];
            (
                l["id"].as_u64().unwrap(),
                [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()],
            )
        })
        .collect()
}

#[test]
fn a_bag_of_the_office_imports_as_its_run_and_surveys_alike() {
    let run = office_run();
    let dir = tempfile::tempdir().unwrap();
    let (bag, imported) = (dir.path().join("bag"), dir.path().join("imported"));
    write_bag(run, &bag, &[]);
    ok(&[
        "import",
        "--bag",
        s(&bag),
        "--ground-truth",
        "/ground_truth",
        "--out",
        s(&imported),
    ]);
    // The run the bag was written from: pictures, their times and the sonar to the digit, the
    // odometry (moved to start at (0, 0) in the bag and back to the truth's start pose) to
    // float rounding, the rig from camera_info and tf.
    for f in ["stereo.csv", "sonar.csv"] {
        assert_eq!(text(&run.join(f)), text(&imported.join(f)), "{f}");
    }
    // The transducers' shortest range comes from the Range messages' min_range: readings
    // clamped there are no distances.
    assert!(text(&run.join("run.yaml")).contains("min_range_m: 0.1\n"));
    assert!(text(&imported.join("run.yaml")).contains("min_range_m: 0.1\n"));
    assert_csv_close(
        &run.join("odometry.csv"),
        &imported.join("odometry.csv"),
        2e-5,
    );
    assert_csv_close(
        &run.join("ground_truth.csv"),
        &imported.join("ground_truth.csv"),
        0.0,
    );
    for k in [0, 100, 300] {
        let f = format!("stereo/left/{k:06}.png");
        assert!(
            std::fs::read(run.join(&f)).unwrap() == std::fs::read(imported.join(&f)).unwrap(),
            "{f} differs"
        );
    }
    let (a, b) = (
        stereotag::io::load_rig(&run.join("rig.yaml")).unwrap(),
        stereotag::io::load_rig(&imported.join("rig.yaml")).unwrap(),
    );
    assert_eq!(a.left, b.left);
    assert!(
        (a.right_from_left.translation.vector - b.right_from_left.translation.vector).norm()
            < 1e-12
    );
    let mounting = (a.robot_from_left.to_matrix() - b.robot_from_left.to_matrix()).norm();
    assert!(mounting < 1e-8, "robot_from_left differs by {mounting:e}");
    let summary = json(&imported.join("import.json"));
    assert_eq!(summary["unmatched_left"], 0);
    // The simulated wheels drift from the ground truth (0.28 m RMS over 55 m): no warning that
    // the odometry follows it.
    let against = &summary["odometry_against_ground_truth"];
    assert_eq!(against["follows"].as_bool(), Some(false), "{summary}");
    assert!(against["rms_m"].as_f64().unwrap() > 0.1, "{summary}");
    assert_eq!(
        summary["pairs"].as_u64().unwrap() as usize,
        text(&run.join("stereo.csv")).lines().count() - 1
    );
    let roles: Vec<&str> = summary["topics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["used_as"].as_str().unwrap())
        .collect();
    assert!(
        roles.contains(&"sonar 4") && roles.contains(&"left camera_info"),
        "{roles:?}"
    );

    // Surveyed alike: the same landmarks and ATE as the run itself.
    same_mapping(run, &imported);
    let world = "samples/office/world.yaml";
    let (sa, sb) = (dir.path().join("survey_run"), dir.path().join("survey_bag"));
    for (r, out) in [(run, &sa), (imported.as_path(), &sb)] {
        ok(&[
            "survey",
            "--run",
            s(r),
            "--world",
            world,
            "--out",
            s(out),
            "--no-rerun",
            "-q",
        ]);
    }
    let (ra, rb) = (json(&sa.join("report.json")), json(&sb.join("report.json")));
    for key in [
        "ate_m.odometry",
        "ate_m.online",
        "ate_m.offline",
        "landmarks.median_error_m",
    ] {
        let (x, y) = (
            ra["metrics"][key].as_f64().unwrap(),
            rb["metrics"][key].as_f64().unwrap(),
        );
        assert!((x - y).abs() < 1e-5, "{key}: run {x}, bag {y}");
    }
    let (la, lb) = (landmarks(&sa), landmarks(&sb));
    assert_eq!(la.len(), lb.len());
    for ((ia, pa), (ib, pb)) in la.iter().zip(&lb) {
        assert_eq!(ia, ib);
        assert!(
            (pa[0] - pb[0]).hypot(pa[1] - pb[1]) < 1e-4,
            "tag {ia}: {pa:?} vs {pb:?}"
        );
    }
}

#[test]
fn compressed_images_other_names_and_a_laser_import_too() {
    let run = office_run();
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    write_bag(
        run,
        &bag,
        &[
            "--compressed",
            "--other-names",
            "--laser",
            "samples/office/world.yaml",
        ],
    );
    let topics = [
        "--left",
        "/cam_l/image_raw/compressed",
        "--right",
        "/cam_r/image_raw/compressed",
        "--odom",
        "/wheel/odometry",
        "--ground-truth",
        "/mocap/robot",
    ];
    // Unnamed, the two odometries are refused with the bag's topics listed.
    let (code, err) = stereotag(&[
        "import",
        "--bag",
        s(&bag),
        "--left",
        "/cam_l/image_raw/compressed",
        "--right",
        "/cam_r/image_raw/compressed",
        "--out",
        s(&dir.path().join("no")),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--odom") && err.contains("/wheel/odometry (nav_msgs/msg/Odometry"),
        "{err}"
    );
    assert!(!dir.path().join("no").exists());

    let sonar = dir.path().join("sonar");
    let mut args = vec![
        "import",
        "--bag",
        s(&bag),
        "--out",
        s(&sonar),
        "--sonar",
        "/range/s*",
    ];
    args.extend(topics);
    ok(&args);
    // The PNGs inside CompressedImage are written as they are; the odometry's child frame
    // (base_footprint) is brought to base_link through tf.
    assert_eq!(
        text(&run.join("stereo.csv")),
        text(&sonar.join("stereo.csv"))
    );
    assert!(
        std::fs::read(run.join("stereo/right/000042.png")).unwrap()
            == std::fs::read(sonar.join("stereo/right/000042.png")).unwrap()
    );
    assert_csv_close(&run.join("odometry.csv"), &sonar.join("odometry.csv"), 2e-5);
    assert_eq!(text(&run.join("sonar.csv")), text(&sonar.join("sonar.csv")));
    // The right camera's pose from tf here (both optical frames are in it).
    assert!(json(&sonar.join("import.json"))["rig_from"]
        .as_str()
        .unwrap()
        .contains("tf (between"));

    // The laser came in as the run's lidar too, and maps: the simulated office's walls, from
    // thin rays on the true poses.
    let lidar = json(&sonar.join("import.json"))["lidar"].clone();
    assert!(lidar["scans"].as_u64().unwrap() > 1000, "{lidar}");
    assert!(text(&sonar.join("run.yaml")).contains("lidar:"));
    let map = dir.path().join("lidar_map");
    ok(&[
        "-q",
        "map",
        "--run",
        s(&sonar),
        "--out",
        s(&map),
        "--poses",
        "ground-truth",
        "--world",
        "samples/office/world.yaml",
    ]);
    let m = json(&map.join("report.json"))["metrics"].clone();
    eprintln!("office lidar map on the true poses: {m}");
    assert_eq!(m["ranging.lidar"].as_f64(), Some(1.0));
    assert!(m["map.occupied_precision"].as_f64().unwrap() >= 0.9, "{m}");
    assert!(m["map.occupied_recall"].as_f64().unwrap() >= 0.9, "{m}");
    // The office's walls are found; of its corners the point Hough transform finds half (on
    // laser returns it peaks all along the walls: docs/RESULTS.md).
    assert!(m["walls"].as_f64().unwrap() >= 6.0, "{m}");
    assert!(m["features.recall"].as_f64().unwrap() >= 0.5, "{m}");
    // Surveyed, then localised on the laser alone (the pictures taken out): its scans matched
    // with the survey's returns hold the robot to centimetres where the odometry drifts
    // decimetres.
    let survey = dir.path().join("lidar_survey");
    ok(&["-q", "survey", "--run", s(&sonar), "--out", s(&survey)]);
    std::fs::write(sonar.join("stereo.csv"), "t_s,left,right\n").unwrap();
    let localized = dir.path().join("lidar_localize");
    ok(&[
        "-q",
        "localize",
        "--run",
        s(&sonar),
        "--survey",
        s(&survey),
        "--out",
        s(&localized),
    ]);
    let m = json(&localized.join("report.json"))["metrics"].clone();
    eprintln!("office localised on the laser alone: {m}");
    assert!(survey.join("returns_corrected.pgm").exists());
    assert!(m["scans.fused"].as_f64().unwrap() > 500.0, "{m}");
    assert!(m["ate_m.localized"].as_f64().unwrap() < 0.03, "{m}");
    assert!(m["ate_m.odometry"].as_f64().unwrap() > 0.1, "{m}");

    // The laser as the paper's five sonars: one reading per sonar and scan, and near the
    // simulated sonar's echoes where both have one.
    let laser = dir.path().join("laser");
    let mut args = vec![
        "import",
        "--bag",
        s(&bag),
        "--out",
        s(&laser),
        "--as-sonar",
        "frontal5",
        "--scan",
        "/scan",
    ];
    args.extend(topics);
    ok(&args);
    let summary = json(&laser.join("import.json"));
    let scans = summary["scans"].as_u64().unwrap();
    assert!(scans > 1000, "{summary}");
    assert_eq!(summary["readings"].as_u64().unwrap(), 5 * scans);
    let echoes = |p: &Path| -> std::collections::HashMap<(i64, i64), f64> {
        csv_numbers(&p.join("sonar.csv"))
            .into_iter()
            .filter(|r| r[2].is_finite())
            .map(|r| (((r[0] * 1e4).round() as i64, r[1] as i64), r[2]))
            .collect()
    };
    let (simulated, from_laser) = (echoes(run), echoes(&laser));
    let both: Vec<f64> = simulated
        .iter()
        .filter_map(|(k, r)| from_laser.get(k).map(|q| (r - q).abs()))
        .collect();
    assert!(
        both.len() > 500,
        "{} readings with echoes in both",
        both.len()
    );
    let mut sorted = both.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let near = both.iter().filter(|&&d| d < 0.1).count() as f64 / both.len() as f64;
    // The simulated sonar has range noise, reflects specularly off walls met at a slant and sees
    // people; the laser sees every wall in the cone: their echoes agree at the median, and most
    // within 10 cm (a mirrored or shifted laser would not: metres off).
    assert!(median < 0.03, "median difference {median:.3} m");
    assert!(
        near > 0.6,
        "{:.2} of {} echoes within 10 cm",
        near,
        both.len()
    );
}

/// `import` of a broken bag: exit 2, the message names the bag and what is wrong, no output.
fn refused(bag: &Path, extra: &[&str], expect: &[&str]) {
    let out = bag.with_extension("out");
    let mut args = vec![
        "import",
        "--bag",
        s(bag),
        "--out",
        s(&out),
        "--ground-truth",
        "/ground_truth",
    ];
    args.extend(extra);
    let (code, err) = stereotag(&args);
    assert_eq!(code, 2, "{}: {err}", bag.display());
    for e in expect {
        assert!(
            err.contains(e),
            "{}: expected `{e}` in: {err}",
            bag.display()
        );
    }
    assert!(!out.exists(), "{} was written", out.display());
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn broken_bags_are_refused_naming_what_is_wrong() {
    let run = office_run();
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good");
    write_bag(run, &good, &["--pairs", "3"]);
    let mcap = good.join("good.mcap");
    let bytes = std::fs::read(&mcap).unwrap();
    // Truncated, and a flipped byte inside the first chunk (its CRC then fails).
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    refused(&cut, &[], &["cut.mcap", "cut short"]);
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 4] ^= 0xff;
    let crc = dir.path().join("crc.mcap");
    std::fs::write(&crc, &flipped).unwrap();
    refused(&crc, &[], &["crc.mcap", "CRC"]);
    // A missing topic: the bag's topics and types are listed.
    refused(
        &good,
        &["--odom", "/nope"],
        &[
            "--odom /nope: no such topic",
            "/odom (nav_msgs/msg/Odometry, 7 messages)",
        ],
    );
    for (what, expect) in [
        (
            "encoding",
            &["/stereo/left/image_raw, message 0", "bayer_rggb8"][..],
        ),
        (
            "right-size",
            &["640 x 480", "320 x 240", "/stereo/right/image_raw"][..],
        ),
        (
            "no-tf",
            &["sonar_2", "/sonar/2", "frames in /tf and /tf_static"][..],
        ),
        (
            "info-size",
            &["/stereo/left/camera_info says 656 x 480", "640 x 480"][..],
        ),
    ] {
        let bag = dir.path().join(what);
        write_bag(run, &bag, &["--pairs", "3", "--break", what]);
        refused(&bag, &[], expect);
    }
    // zstd-compressed chunks (rosbags-convert --compress zstd) read alike.
    let zstd = dir.path().join("zstd");
    let status = Command::new("python3")
        .args([
            "-m",
            "rosbags.convert",
            "--src",
            s(&good),
            "--dst",
            s(&zstd),
        ])
        .args([
            "--dst-storage",
            "mcap",
            "--compress",
            "zstd",
            "--compress-mode",
            "storage",
        ])
        .status()
        .unwrap();
    assert!(status.success());
    let (plain, packed) = (dir.path().join("plain_run"), dir.path().join("zstd_run"));
    for (bag, out) in [(&good, &plain), (&zstd, &packed)] {
        ok(&[
            "import",
            "--bag",
            s(bag),
            "--ground-truth",
            "/ground_truth",
            "--out",
            s(out),
        ]);
    }
    for f in [
        "stereo.csv",
        "odometry.csv",
        "sonar.csv",
        "stereo/left/000002.png",
    ] {
        assert!(
            std::fs::read(plain.join(f)).unwrap() == std::fs::read(packed.join(f)).unwrap(),
            "{f}"
        );
    }
    // A ROS 1 bag is pointed to the converter.
    let ros1 = dir.path().join("old.bag");
    std::fs::write(&ros1, b"#ROSBAG V2.0\n").unwrap();
    refused(&ros1, &[], &["ROS 1", "rosbags-convert"]);
}

/// The run as an ASL folder (`mav0/cam{0,1}` with data.csv, data/ and sensor.yaml, the ground
/// truth in `state_groundtruth_estimate0`) and its odometry as a TUM file, stamped from 1.7e9 s.
fn write_asl(run: &Path, out: &Path) -> PathBuf {
    const BASE_NS: i64 = 1_700_000_000_000_000_000;
    let ns = |t: f64| BASE_NS + (t * 1e9).round() as i64;
    let mav = out.join("mav0");
    let rig = stereotag::io::load_rig(&run.join("rig.yaml")).unwrap();
    let rows: Vec<Vec<String>> = text(&run.join("stereo.csv"))
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    for (k, (camera, body_from_camera)) in [
        (rig.left, rig.robot_from_left),
        (rig.right, rig.robot_from_left * rig.left_from_right()),
    ]
    .into_iter()
    .enumerate()
    {
        let dir = mav.join(format!("cam{k}"));
        std::fs::create_dir_all(dir.join("data")).unwrap();
        let mut list = String::from("#timestamp [ns],filename\n");
        for r in &rows {
            let stamp = ns(r[0].parse().unwrap());
            list += &format!("{stamp},{stamp}.png\n");
            std::os::unix::fs::symlink(
                run.join(&r[1 + k]),
                dir.join("data").join(format!("{stamp}.png")),
            )
            .unwrap();
        }
        std::fs::write(dir.join("data.csv"), list).unwrap();
        let m = body_from_camera.to_matrix();
        let t_bs: Vec<String> = (0..4)
            .flat_map(|i| (0..4).map(move |j| (i, j)))
            .map(|(i, j)| format!("{:.17}", m[(i, j)]))
            .collect();
        let stereotag::camera::Distortion::Radtan { k1, k2, p1, p2, .. } = camera.distortion else {
            panic!("the simulated rig is radtan");
        };
        std::fs::write(
            dir.join("sensor.yaml"),
            format!(
                "sensor_type: camera\ncomment: simulated\nT_BS:\n  cols: 4\n  rows: 4\n  data: [{}]\nrate_hz: 20\nresolution: [{}, {}]\ncamera_model: pinhole\nintrinsics: [{}, {}, {}, {}]\ndistortion_model: radial-tangential\ndistortion_coefficients: [{k1}, {k2}, {p1}, {p2}]\n",
                t_bs.join(", "), camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
            ),
        )
        .unwrap();
    }
    let truth = mav.join("state_groundtruth_estimate0");
    std::fs::create_dir_all(&truth).unwrap();
    let mut gt = String::from("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n");
    for r in csv_numbers(&run.join("ground_truth.csv")) {
        let (qz, qw) = (0.5 * r[3]).sin_cos();
        gt += &format!(
            "{},{:.9},{:.9},0,{qw:.12},0,0,{qz:.12}\n",
            ns(r[0]),
            r[1],
            r[2]
        );
    }
    std::fs::write(truth.join("data.csv"), gt).unwrap();
    let tum = out.join("odometry.tum");
    poses_as_tum(&run.join("odometry.csv"), &tum);
    tum
}

/// A run's poses (`odometry.csv`, `ground_truth.csv`) as a TUM file, stamped from 1.7e9 s.
fn poses_as_tum(csv: &Path, tum: &Path) {
    let poses: Vec<stereotag::geometry::StampedPose> = csv_numbers(csv)
        .iter()
        .map(|r| stereotag::geometry::StampedPose {
            t_s: 1.7e9 + r[0],
            pose: stereotag::geometry::Pose2::new(r[1], r[2], r[3]),
        })
        .collect();
    stereotag::io::save_tum(tum, &poses).unwrap();
}

#[test]
fn an_asl_folder_imports_as_its_run_and_surveys_alike() {
    let run = office_run();
    let dir = tempfile::tempdir().unwrap();
    let (asl, imported) = (dir.path().join("asl"), dir.path().join("imported"));
    let tum = write_asl(run, &asl);
    // Without odometry: refused, saying how to give it.
    let (code, err) = stereotag(&["import", "--asl", s(&asl), "--out", s(&imported)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--odometry") && !imported.exists(), "{err}");
    ok(&[
        "import",
        "--asl",
        s(&asl),
        "--odometry",
        s(&tum),
        "--out",
        s(&imported),
    ]);
    // The simulated wheels drift from the truth: nothing said. The ground truth itself given
    // as the odometry (a shortcut that tests nothing) is warned about, and import.json says so.
    let against = &json(&imported.join("import.json"))["odometry_against_ground_truth"];
    assert_eq!(against["follows"].as_bool(), Some(false), "{against}");
    let truth_tum = dir.path().join("truth.tum");
    poses_as_tum(&run.join("ground_truth.csv"), &truth_tum);
    let on_truth = dir.path().join("on_truth");
    let (code, err) = stereotag(&[
        "import",
        "--asl",
        s(&asl),
        "--odometry",
        s(&truth_tum),
        "--out",
        s(&on_truth),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("as no wheel odometry does"), "{err}");
    let against = &json(&on_truth.join("import.json"))["odometry_against_ground_truth"];
    assert_eq!(against["follows"].as_bool(), Some(true), "{against}");
    let times = |p: &Path| -> Vec<f64> {
        csv_numbers(&p.join("stereo.csv"))
            .iter()
            .map(|r| r[0])
            .collect()
    };
    assert_eq!(times(run), times(&imported));
    assert_csv_close(
        &run.join("odometry.csv"),
        &imported.join("odometry.csv"),
        2e-5,
    );
    assert_csv_close(
        &run.join("ground_truth.csv"),
        &imported.join("ground_truth.csv"),
        2e-5,
    );
    let first = text(&imported.join("stereo.csv"))
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(2)
        .unwrap()
        .to_owned();
    assert!(
        std::fs::read(run.join("stereo/right/000000.png")).unwrap()
            == std::fs::read(imported.join(first)).unwrap()
    );
    let (a, b) = (
        stereotag::io::load_rig(&run.join("rig.yaml")).unwrap(),
        stereotag::io::load_rig(&imported.join("rig.yaml")).unwrap(),
    );
    assert_eq!(a.left, b.left);
    assert!((a.right_from_left.to_matrix() - b.right_from_left.to_matrix()).norm() < 1e-9);
    assert!((a.robot_from_left.to_matrix() - b.robot_from_left.to_matrix()).norm() < 1e-8);
    // No sonar: the same landmarks as the run's survey within millimetres (the sonar barely
    // moves a survey of tags).
    let world = "samples/office/world.yaml";
    let (sa, sb) = (dir.path().join("survey_run"), dir.path().join("survey_asl"));
    for (r, out) in [(run, &sa), (imported.as_path(), &sb)] {
        ok(&[
            "survey",
            "--run",
            s(r),
            "--world",
            world,
            "--out",
            s(out),
            "--no-rerun",
            "-q",
        ]);
    }
    let (la, lb) = (landmarks(&sa), landmarks(&sb));
    assert_eq!(la.len(), lb.len());
    for ((ia, pa), (ib, pb)) in la.iter().zip(&lb) {
        assert_eq!(ia, ib);
        assert!(
            (pa[0] - pb[0]).hypot(pa[1] - pb[1]) < 5e-3,
            "tag {ia}: {pa:?} vs {pb:?}"
        );
    }
    let ate = |p: &Path| {
        json(&p.join("report.json"))["metrics"]["ate_m.offline"]
            .as_f64()
            .unwrap()
    };
    assert!(
        (ate(&sa) - ate(&sb)).abs() < 3e-3,
        "offline ATE {} vs {}",
        ate(&sa),
        ate(&sb)
    );
}
