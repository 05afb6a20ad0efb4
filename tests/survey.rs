//! The survey end to end through the library's workflows: the demo on the office (simulate,
//! render, detect, triangulate, fuse online and offline, rebuild the map, record), checked against
//! the figures of the fusion issue and the Rerun recording read back with the `rerun` CLI; a later
//! run localised against it; tags planned on a sonar map.

use serde_json::Value;
use std::path::Path;
use std::process::Command;
use stereotag::dataset::PoseSource;
use stereotag::progress::Silent;
use stereotag::visual::tags::Backend;
use stereotag::viz::RecordingRequest;
use stereotag::workflow::sightings::DetectOptions;
use stereotag::workflow::simulate::{Pictures, SimSettings, SimulateRequest};

/// Offline ATE at most this share of odometry's (the figure).
const OFFLINE_ATE_RATIO: f64 = 0.2;
/// Offline ATE on the office, metres (the figure).
const OFFLINE_ATE_OFFICE_M: f64 = 0.05;
/// Online ATE at most this share of odometry's (the figure).
const ONLINE_ATE_RATIO: f64 = 0.5;
/// The corrected map's occupied precision and recall within this of the ground-truth-pose map's
/// (the figure; this run, the demo's office seed 1, is within 0.006 since the grid has a
/// margin below the outer walls).
const MAP_GAP: f64 = 0.05;
/// Landmark median error, metres (the figure; the office seeds give 0.3-0.7 cm since the
/// cameras' turns hold the heading, 1.5-8.0 cm before).
const LANDMARK_MEDIAN_M: f64 = 0.03;
/// RMS error of the turns the visual odometry measured, degrees (the office seeds: 0.03; the
/// wheels over the same pairs of pictures: 0.3).
const VISUAL_TURN_RMS_DEG: f64 = 0.1;

fn stereotag() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_stereotag"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

/// The `rerun` CLI: `$RERUN` (set by `.ci/run`) or `rerun` on PATH.
fn rerun() -> Command {
    Command::new(std::env::var("RERUN").unwrap_or_else(|_| "rerun".into()))
}

/// `rerun rrd print -vvv` of a recording that `rerun rrd verify` accepts.
fn verified_recording(rrd: &Path) -> String {
    let verify = rerun()
        .args(["rrd", "verify"])
        .arg(rrd)
        .output()
        .expect("the `rerun` CLI (pip install rerun-sdk==0.36.3) must be on PATH");
    assert!(
        verify.status.success(),
        "rerun rrd verify {}: {}",
        rrd.display(),
        String::from_utf8_lossy(&verify.stderr)
    );
    let print = rerun()
        .args(["rrd", "print", "-vvv"])
        .arg(rrd)
        .output()
        .unwrap();
    assert!(print.status.success());
    String::from_utf8_lossy(&print.stdout).into_owned()
}

fn metric(report: &Value, key: &str) -> f64 {
    report["metrics"][key]
        .as_f64()
        .unwrap_or_else(|| panic!("report.json has no metric {key}"))
}

fn read_report(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

/// The demo (the office simulated with pictures, then surveyed and recorded) into `out`.
fn run_demo(out: &Path, seed: u64) -> Value {
    demo_of(
        Path::new("samples/office/world.yaml"),
        None,
        out,
        seed,
        true,
    )
}

/// The mean of (error / sigma)² of a survey's corrected walls, over the faces with a sigma and 20
/// ranges of `run_dir` (its ground-truth poses) matched with them, and their count. A face's
/// error is the median misfit of its ranges (measured minus expected at the true pose).
fn wall_placement_z2(survey: &Path, run_dir: &Path) -> (f64, usize) {
    use stereotag::fusion::{wall_misfits, SonarInput, RANGE_OFF_M};
    let walls = stereotag::io::load_walls_csv(&survey.join("walls_corrected.csv")).unwrap();
    let run = stereotag::io::load_run(run_dir).unwrap();
    let sonar = SonarInput {
        readings: &run.sonar,
        layout: &run.meta.robot.sonar,
        walls: &walls,
        walls_covariance: None,
    };
    let mut misfits = wall_misfits(&sonar, run.ground_truth.as_ref().unwrap());
    for m in &mut misfits {
        m.retain(|e| e.abs() <= RANGE_OFF_M);
    }
    let z2: Vec<f64> = walls
        .iter()
        .zip(&mut misfits)
        .filter(|(w, m)| w.sigma_m.is_some() && m.len() >= 20)
        .map(|(w, m)| {
            m.sort_by(f64::total_cmp);
            (m[m.len() / 2] / w.sigma_m.unwrap()).powi(2)
        })
        .collect();
    (z2.iter().sum::<f64>() / z2.len().max(1) as f64, z2.len())
}

/// The demo's steps on `world` (pictures with `rig`, else the default one) into `out`, recorded
/// if `record`.
fn demo_of(world: &Path, rig: Option<&Path>, out: &Path, seed: u64, record: bool) -> Value {
    stereotag::workflow::demo::demo(
        &stereotag::workflow::demo::DemoRequest {
            world,
            out,
            seed: Some(seed),
            rig,
            detect: DetectOptions::survey(Backend::ApriltagC),
            force: false,
            recording: if record {
                RecordingRequest::default()
            } else {
                RecordingRequest::none()
            },
        },
        &Silent,
    )
    .expect("the demo runs");
    read_report(out)
}

/// `world` simulated into `out` with `settings`, with pictures (the default rig) unless
/// `no_stereo`.
fn simulate(world: &Path, out: &Path, settings: SimSettings, no_stereo: bool) {
    stereotag::workflow::simulate::simulate(
        &SimulateRequest {
            world,
            out,
            settings,
            pictures: (!no_stereo).then(|| Pictures {
                rig: Path::new(stereotag::io::DEFAULT_RIG),
                policy: Default::default(),
                default_mounting: false,
            }),
            force: false,
            along: None,
        },
        &Silent,
    )
    .expect("the simulation runs");
}

/// `survey` of `run` into `out` with the defaults, silent.
fn survey_run(run: &Path, out: &Path) -> stereotag::workflow::survey::SurveyOutput {
    stereotag::workflow::survey::survey(
        &stereotag::workflow::survey::SurveyRequest::new(run, out),
        &Silent,
    )
    .expect("the run is surveyed")
}

/// The sonar map of `run` into `out`, with its recording (`map.rrd`).
fn map(run: &Path, out: &Path, poses: PoseSource) {
    stereotag::workflow::map::map(
        &stereotag::workflow::map::MapRequest {
            run_dir: run,
            out,
            poses,
            world: None,
            config: None,
            force: false,
            recording: stereotag::viz::RecordingRequest::default(),
        },
        &stereotag::progress::Silent,
    )
    .expect("the map is made");
}

/// `plan` on `map` into `out`, predicting with `tags` when given.
fn plan(map: &Path, out: &Path, tags: Option<&Path>, no_walls: bool) {
    stereotag::workflow::plan::plan(&stereotag::workflow::plan::PlanRequest {
        map,
        out: Some(out),
        config: Default::default(),
        tags,
        no_walls,
        force: false,
        recording: Default::default(),
    })
    .expect("the plan is made");
}

/// The printed edge of the office's tags (samples/office/world.yaml).
const OFFICE_TAG_SIZE_M: f64 = 0.16;

#[test]
fn office_survey_meets_the_figures_and_records_what_it_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let report = run_demo(&out, 1);

    let odometry = metric(&report, "ate_m.odometry");
    let online = metric(&report, "ate_m.online");
    let offline = metric(&report, "ate_m.offline");
    assert!(
        odometry > 0.1,
        "odometry ATE {odometry}: the run should drift"
    );
    assert!(
        online <= ONLINE_ATE_RATIO * odometry,
        "online {online} vs odometry {odometry}"
    );
    assert!(
        offline <= OFFLINE_ATE_RATIO * odometry,
        "offline {offline} vs odometry {odometry}"
    );
    assert!(offline <= OFFLINE_ATE_OFFICE_M, "offline ATE {offline}");
    for k in ["occupied_precision", "occupied_recall"] {
        let raw = metric(&report, &format!("map.{k}"));
        let corrected = metric(&report, &format!("map_corrected.{k}"));
        let truth = metric(&report, &format!("map_ground_truth.{k}"));
        assert!(corrected > raw, "{k}: corrected {corrected} raw {raw}");
        assert!(
            corrected >= truth - MAP_GAP,
            "{k}: corrected {corrected} truth {truth}"
        );
    }
    let median = metric(&report, "landmarks.median_error_m");
    assert!(
        median <= LANDMARK_MEDIAN_M,
        "landmark median error {median}"
    );
    // The simulated sonar's ranges lie on the surveyed walls (a real building's do not: 16% of
    // freiburg-079's lie over 10 cm off, `import_carmen`).
    assert!(metric(&report, "walls.ranges_matched") > 500.0);
    assert!(metric(&report, "walls.ranges_off_share") < 0.01);
    assert!(metric(&report, "walls.range_residual_sigma_m") < 0.025);
    assert!(!stereotag::fusion::scatter_too_wide(
        metric(&report, "walls.ranges_off_share"),
        metric(&report, "walls.range_residual_sigma_m"),
        metric(&report, "walls.range_sigma_assumed_m")
    ));
    // The walls' placement sigmas (walls_corrected.csv's sigma_m, from the offline trajectory's
    // covariance) are the size of their errors: mean (error / sigma)² 1.21 over the 10 faces
    // (true errors 0.5 cm RMS, sigmas 0.5 cm); a sigma off by a factor of 1.6 either way fails.
    let (z2, faces) = wall_placement_z2(&out, &out.join("run"));
    assert!(faces >= 8, "{faces} faces placed and seen 20 times");
    assert!((0.4..=2.5).contains(&z2), "mean (error / sigma)² {z2}");
    assert!(metric(&report, "walls.placed") >= 8.0);
    let turns = metric(&report, "visual.turns");
    let turn_rms = metric(&report, "visual.turn_error_rms_deg");
    assert!(turns > 500.0, "{turns} visual turns");
    assert!(
        turn_rms < VISUAL_TURN_RMS_DEG,
        "visual turns RMS {turn_rms} degrees"
    );
    assert!(metric(&report, "visual.fused_online") > 0.9 * turns);

    // landmarks.json, layout.json and trajectory.csv as DESIGN.md fixes them.
    let landmarks: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("landmarks.json")).unwrap())
            .unwrap();
    let list = landmarks["landmarks"].as_array().unwrap();
    assert_eq!(list.len(), 2);
    for l in list {
        for key in [
            "id",
            "family",
            "size_m",
            "position_m",
            "yaw_rad",
            "covariance_m2",
            "observations",
            "matched_corner",
            "planned_position_m",
        ] {
            assert!(l.get(key).is_some(), "landmarks.json lacks {key}: {l}");
        }
        // The size used is the world's printed size; the triangulated one is reported beside it.
        let (used, triangulated) = (
            l["size_m"].as_f64().unwrap(),
            l["size_triangulated_m"].as_f64().unwrap(),
        );
        assert_eq!(used, OFFICE_TAG_SIZE_M, "{l}");
        assert!(
            (triangulated - used).abs() < 0.15 * used && triangulated != used,
            "{l}"
        );
    }
    let layout: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("layout.json")).unwrap()).unwrap();
    assert_eq!(layout["tags"].as_array().unwrap().len(), 2);
    assert!(layout["tags"][0]["pose"]["rotation"]["quaternion"]["W"].is_number());
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    assert!(csv.starts_with(
        "t_s,odom_x_m,odom_y_m,odom_theta_rad,online_x_m,online_y_m,online_theta_rad,\
         offline_x_m,offline_y_m,offline_theta_rad,gt_x_m,gt_y_m,gt_theta_rad\n"
    ));
    for f in [
        "map.pgm",
        "map.yaml",
        "map_online.pgm",
        "map_online.yaml",
        "map_corrected.pgm",
        "map_corrected.yaml",
        "corners.csv",
        "walls_corrected.csv",
        "visual_turns.csv",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let turns_csv = std::fs::read_to_string(out.join("visual_turns.csv")).unwrap();
    assert!(turns_csv.starts_with(stereotag::io::VISUAL_TURNS_HEADER));

    // The recording: verified and read back by the rerun CLI of the crate's version.
    let rrd = out.join("survey.rrd");
    let size = std::fs::metadata(&rrd).unwrap().len();
    assert!(size < 50_000_000, "survey.rrd is {size} bytes");
    let text = verified_recording(&rrd);
    for entity in [
        "/world/walls",
        "/world/trajectories/offline",
        "/world/robot",
        "/world/robot/left/image",
        "/world/robot/right/image",
        "/world/robot/left/image/tags",
        "/world/sonar/beams",
        "/world/grid",
        "/map/online/grid",
        "/map/corrected/grid",
        "/map/corrected/walls",
        "/world/walls_surveyed",
        "/map/hough",
        "/landmarks/tag_0/covariance",
        "/metrics/position_error_m/offline",
        "/metrics/turn_deg/visual_error",
        "/metrics/turn_deg/wheels_error",
        "/events/online_resolve",
        "/report",
        // The top-down map with every trajectory and the landmarks, and the picture with a tag.
        "/map/corrected/trajectories/odometry",
        "/map/corrected/trajectories/offline",
        "/map/corrected/landmarks",
        "/map/corrected/legend",
        "/tag_frame/left/image",
        "/tag_frame/left/image/tags",
        // The layout the viewer opens it with: its own views' settings too.
        "/viewport",
        "/time_panel",
    ] {
        assert!(
            text.contains(&format!("- {entity} - ")),
            "the recording has no {entity}"
        );
    }
    assert!(
        text.contains("/VisibleTimeRanges - ") && text.contains("/EyeControls3D - "),
        "the layout sets no plot range or 3D eye"
    );
    for l in list {
        let id = l["id"].as_u64().unwrap();
        let recorded = recorded_position(&text, &format!("/landmarks/tag_{id}"))
            .unwrap_or_else(|| panic!("no position logged for tag {id}"));
        for (axis, value) in recorded.iter().enumerate() {
            let expected = l["position_m"][axis].as_f64().unwrap();
            // Rerun stores f32.
            assert!(
                (value - expected).abs() < 1e-5,
                "tag {id} axis {axis}: recorded {value}, landmarks.json {expected}"
            );
        }
    }
    // `plan` on the survey reads its corrected map, corners and walls, all in one frame, and
    // finds nothing to warn about.
    let plan_dir = dir.path().join("plan");
    plan(&out, &plan_dir, None, false);
    let planned: Value =
        serde_json::from_str(&std::fs::read_to_string(plan_dir.join("plan.json")).unwrap())
            .unwrap();
    let files = &planned["map_files"];
    assert_eq!(files["corrected"], true, "{files}");
    for (key, name) in [
        ("map", "map_corrected.yaml"),
        ("corners", "corners_corrected.csv"),
        ("walls", "walls_corrected.csv"),
    ] {
        assert!(files[key].as_str().unwrap().ends_with(name), "{files}");
    }
    assert_eq!(planned["warnings"], serde_json::json!([]), "{planned}");
}

/// The first `[[x, y, z]]` row of the chunk logged at `entity` in `rerun rrd print -vvv` output.
fn recorded_position(text: &str, entity: &str) -> Option<[f64; 3]> {
    let header = format!("- {entity} - ");
    let start = text.find(&header)?;
    let row = text[start..].lines().find(|l| l.contains("row_"))?;
    let inner = row.split("[[").nth(1)?.split("]]").next()?;
    let v: Vec<f64> = inner
        .split(',')
        .map(|s| s.trim().parse().ok())
        .collect::<Option<_>>()?;
    Some([*v.first()?, *v.get(1)?, *v.get(2)?])
}

#[test]
fn survey_refuses_an_existing_output_and_keeps_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("kept");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("mine.txt"), "keep me").unwrap();
    let output = stereotag()
        .args(["survey", "--run", "samples/office", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains("already exists"), "{err}");
    assert_eq!(
        std::fs::read_to_string(out.join("mine.txt")).unwrap(),
        "keep me"
    );
}

/// The ground truth of a simulated run.
fn ground_truth(run_dir: &Path) -> Vec<stereotag::geometry::StampedPose> {
    let run = stereotag::workflow::load_run(run_dir).unwrap();
    run.ground_truth
        .expect("a simulated run has its ground truth")
}

/// `run_dir` fed to a `StereoLocalizer` against `survey` as a robot feeds it: odometry, sonar
/// and stereo pairs merged in time order (each pair read when its turn comes). The pose after
/// each odometry pose, and the mean position NEES (as `localize` reports it: `e² / (2 σ²)` with
/// the worst-direction sigma) against the ground truth.
fn stream_localise(survey: &Path, run_dir: &Path) -> (Vec<stereotag::geometry::StampedPose>, f64) {
    use stereotag::fusion::{FuseConfig, Start, StereoLocalizer};
    use stereotag::geometry::{pose_at, StampedPose};
    use stereotag::visual::tags::{DetectorConfig, TagFamily};
    use stereotag::workflow::localize::{SurveyUse, SurveyedMap};
    let map = SurveyedMap::load(survey, SurveyUse::default()).unwrap();
    assert!(
        map.calibration.is_some(),
        "the survey calibrated the odometry"
    );
    assert!(
        map.noise_scale.is_some(),
        "the survey measured the odometry's noise"
    );
    assert!(
        map.walls_covariance.is_some(),
        "the survey placed its walls"
    );
    let run = stereotag::workflow::load_run(run_dir).unwrap();
    let rig = stereotag::workflow::survey::load_run_rig(run_dir, &run, false)
        .unwrap()
        .expect("the run has pictures");
    // As `localize` predicts: the calibrated odometry's noise, scaled as the survey measured it.
    let filter = map.localizer(
        FuseConfig::default(),
        Start::Survey,
        Some(&run.meta.robot.sonar),
    );
    let detector = Backend::ApriltagC
        .detector(DetectorConfig {
            families: vec![TagFamily::Tag36h11],
            decimate: stereotag::workflow::sightings::survey_decimate(Backend::ApriltagC),
            min_contrast: stereotag::workflow::sightings::SURVEY_MIN_CONTRAST,
            ..DetectorConfig::default()
        })
        .unwrap();
    let mut localizer = StereoLocalizer::new(filter, rig, detector);
    // (time, what: 0 odometry, 1 range, 2 pair, index): at one time the odometry comes first.
    let mut inputs: Vec<(f64, u8, usize)> = Vec::new();
    inputs.extend(run.odometry.iter().enumerate().map(|(i, p)| (p.t_s, 0, i)));
    inputs.extend(run.sonar.iter().enumerate().map(|(i, r)| (r.t_s, 1, i)));
    inputs.extend(run.stereo.iter().enumerate().map(|(i, e)| (e.t_s, 2, i)));
    inputs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let truth = run.ground_truth.as_deref().unwrap();
    let (mut trajectory, mut nees) = (Vec::new(), Vec::new());
    for (t_s, what, i) in inputs {
        match what {
            0 => {
                let now = localizer.odometry(t_s, run.odometry[i].pose);
                trajectory.push(StampedPose {
                    t_s,
                    pose: now.pose,
                });
                let gt = pose_at(truth, t_s).unwrap();
                let c = &now.covariance;
                nees.push(stereotag::metrics::position_nees(
                    [now.pose.x - gt.x, now.pose.y - gt.y],
                    [c[(0, 0)], c[(0, 1)], c[(1, 1)]],
                ));
            }
            1 => {
                localizer.range(&run.sonar[i]);
            }
            _ => {
                let entry = &run.stereo[i];
                let left = stereotag::io::load_gray(&run_dir.join(&entry.left)).unwrap();
                let right = stereotag::io::load_gray(&run_dir.join(&entry.right)).unwrap();
                localizer.stereo_pair(t_s, &left, &right).unwrap();
            }
        }
    }
    let mean = nees.iter().sum::<f64>() / nees.len() as f64;
    (trajectory, mean)
}

#[test]
fn a_later_run_localises_against_the_survey() {
    let dir = tempfile::tempdir().unwrap();
    let survey = dir.path().join("survey");
    run_demo(&survey, 1);
    // A second day: another seed, the same home, the same start.
    let run = dir.path().join("run2");
    let seed_2 = SimSettings {
        seed: Some(2),
        ..SimSettings::default()
    };
    simulate(
        Path::new("samples/office/world.yaml"),
        &run,
        seed_2.clone(),
        false,
    );
    // Localised with the walls or with the tags alone, recorded or not.
    let localize_run = |run: &Path, out: &str, walls: bool, record: bool| -> Value {
        let loc = dir.path().join(out);
        let output = stereotag::workflow::localize::localize(
            &stereotag::workflow::localize::LocalizeRequest {
                survey: &survey,
                run_dir: run,
                out: &loc,
                world: None,
                config: None,
                detect: DetectOptions::survey(Backend::ApriltagC),
                raw_odometry: false,
                no_walls: !walls,
                start: Default::default(),
                force: false,
                recording: if record {
                    RecordingRequest::default()
                } else {
                    RecordingRequest::none()
                },
            },
            &Silent,
        )
        .expect("the run is localised");
        // What `localize` prints and its recording opens with: what it fused and how well.
        let said = |what: &str| output.summary.iter().any(|l| l.contains(what));
        assert!(
            said("ATE: odometry") && said("position NEES"),
            "{:?}",
            output.summary
        );
        assert_eq!(said("sonar ranges fused against"), walls);
        // An honest sigma (NEES near 1) gets no hint why it would be overconfident.
        assert!(!said("overconfident: either"), "{:?}", output.summary);
        // Nothing to warn of but, for the run moved away from its world, that the world is gone.
        assert!(
            output
                .warnings
                .iter()
                .all(|w| w.contains("names the world") && w.contains("which is not there")),
            "{:?}",
            output.warnings
        );
        read_report(&loc)
    };
    let report = localize_run(&run, "loc", true, true);
    let odometry = metric(&report, "ate_m.odometry");
    let localised = metric(&report, "ate_m.localized");
    assert!(
        localised <= ONLINE_ATE_RATIO * odometry,
        "localised {localised} vs odometry {odometry}"
    );
    // Issue 5's figure: a second office run keeps ATE <= 5 cm (measured 1.3 cm), with its heading
    // held by visual odometry and its sonar ranges held to the survey's walls between sightings;
    // with the tags and visual odometry alone, 3.3 cm. 23 ranges are fused (101 when the filter
    // predicted with the odometry noise model instead of the survey's measure of it: a range is
    // not fused where the filter knows its distance to the wall better than the wall is known).
    assert!(metric(&report, "walls.surveyed") >= 5.0);
    assert!(metric(&report, "ranges.fused") >= 15.0);
    assert!(localised <= 0.05, "localised {localised}");
    let tags_only = metric(
        &localize_run(&run, "loc_tags", false, false),
        "ate_m.localized",
    );
    assert!(
        localised < tags_only,
        "{localised} vs tags only {tags_only}"
    );
    // The same run fed to the streaming localiser as a robot feeds it, one odometry pose, range
    // and stereo pair at a time (each pair detected as it comes): as good as `localize` over the
    // finished run, within 1 cm, and its covariance as honest.
    let (streamed, nees) = stream_localise(&survey, &run);
    let streamed_ate = stereotag::metrics::ate_m(&streamed, &ground_truth(&run)).unwrap();
    eprintln!(
        "streamed: ATE {streamed_ate:.4} m (localize {localised:.4} m), position NEES mean {nees:.2} (localize {:.2})",
        metric(&report, "nees.position_mean")
    );
    assert!(
        (streamed_ate - localised).abs() <= 0.01 && streamed_ate <= 0.05,
        "streamed {streamed_ate} vs localize {localised}"
    );
    assert!((0.05..=2.0).contains(&nees), "streamed NEES {nees}");
    // `plan --tags` predicts this error from a map of the home and the surveyed tags, with the
    // walls and without: RMS of the predicted error at the cells the robot drove through, against
    // the RMS error it had there (measured: 1.1 vs 1.0 cm with walls, 3.8 vs 3.7 cm tags only).
    let gt_map = dir.path().join("gt_map");
    map(&survey.join("run"), &gt_map, PoseSource::GroundTruth);
    for (loc, walls) in [("loc", true), ("loc_tags", false)] {
        let out = dir.path().join(format!("plan_{loc}"));
        plan(&gt_map, &out, Some(&survey.join("landmarks.json")), !walls);
        let (predicted, measured) = predicted_and_measured(&gt_map, &out, &dir.path().join(loc));
        let ratio = predicted / measured;
        eprintln!("plan, walls {walls}: predicted {predicted:.3} m, measured {measured:.3} m");
        assert!(
            (0.67..=1.5).contains(&ratio),
            "walls {walls}: predicted {predicted:.3} m vs measured {measured:.3} m"
        );
    }

    // The recording of the localisation, verified and read back by the rerun CLI.
    let text = verified_recording(&dir.path().join("loc/localize.rrd"));
    for entity in [
        "/world/trajectories/localized",
        "/world/walls_surveyed",
        "/world/sonar/ranges",
        "/world/sightings",
        "/landmarks/tag_0",
        "/metrics/position_error_m/localized",
        "/report",
    ] {
        assert!(
            text.contains(&format!("- {entity} - ")),
            "the localisation recording has no {entity}"
        );
    }
    // The survey's odometry calibration (the same simulated robot) was applied and helps on its
    // own (office seed 2: 0.84 m -> 0.25 m).
    assert_eq!(metric(&report, "odometry.calibrated"), 1.0);
    let calibrated = metric(&report, "ate_m.odometry_calibrated");
    assert!(
        calibrated < 0.5 * odometry,
        "calibrated odometry {calibrated} vs raw {odometry}"
    );
    let growth = report["error_growth"].as_array().unwrap();
    assert!(growth.len() >= 2, "{growth:?}");
    // Right after a sighting the filter is surer than far from one.
    let sigma = |b: &Value| b["mean_sigma_m"].as_f64().unwrap();
    assert!(sigma(&growth[0]) < sigma(growth.last().unwrap()));

    // The home changed after the survey: a cabinet against a surveyed wall, a sofa. Their echoes
    // are gated out and the run still localises within 5 cm (measured 2.0 cm; 1.4 with the odometry
    // noise model).
    let office = std::fs::read_to_string("samples/office/world.yaml").unwrap();
    let moved = office.replace(
        "  - polyline_m: [[3.5, 4.35], [3.5, 7.5]]\n",
        "  - polyline_m: [[3.5, 4.35], [3.5, 7.5]]\n  \
         - {polyline_m: [[6.5, 2.0], [7.0, 2.0], [7.0, 3.2], [6.5, 3.2]], closed: true, height_m: 1.0}\n  \
         - {polyline_m: [[0.0, 5.0], [0.8, 5.0], [0.8, 6.5], [0.0, 6.5]], closed: true, height_m: 0.8}\n",
    );
    assert_ne!(moved, office);
    let moved_world = dir.path().join("office_moved.yaml");
    std::fs::write(&moved_world, moved).unwrap();
    let moved_run = dir.path().join("run_moved");
    simulate(&moved_world, &moved_run, seed_2, false);
    let report = localize_run(&moved_run, "loc_moved", true, false);
    let localised = metric(&report, "ate_m.localized");
    assert!(
        localised <= 0.05,
        "localised {localised} in the changed home"
    );
    // 31 gated out and 22 fused (78 and 83 when the filter predicted with the odometry noise
    // model: more of its ranges were matched at all).
    assert!(metric(&report, "ranges.gated_out") > 15.0);

    // The same run once its world is gone (a real robot's run has none): the tags are checked
    // against the sizes the survey used, so the same sightings are fused as with the world.
    std::fs::remove_file(&moved_world).unwrap();
    let without_world = localize_run(&moved_run, "loc_no_world", true, false);
    for key in ["sightings.fused", "sightings.gated_out", "ate_m.localized"] {
        assert_eq!(
            metric(&without_world, key),
            metric(&report, key),
            "{key} without the world"
        );
    }
}

#[test]
fn plan_proposes_tags_from_a_sonar_only_museum_map() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let map = dir.path().join("map");
    simulate(
        Path::new("samples/museum/world.yaml"),
        &run,
        SimSettings {
            no_odometry_noise: true,
            ..SimSettings::default()
        },
        true,
    );
    self::map(&run, &map, PoseSource::Odometry);
    // With the run's ground truth, the map reports its trajectory's error (noise-free odometry:
    // millimetres).
    let ate = metric(&read_report(&map), "ate_m.trajectory");
    assert!(ate < 0.05, "ate {ate}");
    // The map's recording: verified and read back by the rerun CLI.
    let text = verified_recording(&map.join("map.rrd"));
    for entity in [
        "/map/final/grid",
        "/map/final/corners",
        "/map/final/walls",
        "/map/final/trajectories/odometry",
        "/map/final/trajectories/ground_truth",
        "/map/growing/grid",
        "/map/log_odds/grid",
        "/map/hough",
        "/world/walls",
        "/world/sonar/beams",
        "/world/robot",
        "/report",
        "/viewport",
    ] {
        assert!(
            text.contains(&format!("- {entity} - ")),
            "map.rrd has no {entity}"
        );
    }
    let plan_dir = dir.path().join("plan");
    plan(&map, &plan_dir, None, false);
    let plan: Value =
        serde_json::from_str(&std::fs::read_to_string(plan_dir.join("plan.json")).unwrap())
            .unwrap();
    let tags = plan["plan"]["tags"].as_array().unwrap();
    assert!(!tags.is_empty() && tags.len() <= 12, "{tags:?}");
    let coverage = plan["plan"]["coverage"].as_f64().unwrap();
    assert!(coverage > 0.5, "coverage {coverage}");
    // Its recording: the error over the map, the tags, the layout.
    let text = verified_recording(&plan_dir.join("plan.rrd"));
    for entity in [
        "/map/grid",
        "/map/predicted_error",
        "/map/tags",
        "/report",
        "/viewport",
    ] {
        assert!(
            text.contains(&format!("- {entity} - ")),
            "plan.rrd has no {entity}"
        );
    }
    // Chosen tags are apart from each other.
    for (i, a) in tags.iter().enumerate() {
        for b in &tags[i + 1..] {
            let d = (a["x_m"].as_f64().unwrap() - b["x_m"].as_f64().unwrap())
                .hypot(a["y_m"].as_f64().unwrap() - b["y_m"].as_f64().unwrap());
            assert!(d >= 1.5, "{a} and {b} are {d} m apart");
        }
    }
}

#[test]
fn plan_warns_on_a_drifted_map() {
    // The office's sonar on its odometry alone: a drifted map whose corners are not the world's.
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let map = dir.path().join("map");
    simulate(
        Path::new("samples/office/world.yaml"),
        &run,
        SimSettings::default(),
        true,
    );
    self::map(&run, &map, PoseSource::Odometry);
    let precision = metric(&read_report(&map), "features.precision");
    assert!(precision < 0.5, "precision {precision}");
    let plan_dir = dir.path().join("plan");
    plan(&map, &plan_dir, None, false);
    let planned: Value =
        serde_json::from_str(&std::fs::read_to_string(plan_dir.join("plan.json")).unwrap())
            .unwrap();
    assert_eq!(planned["map_files"]["corrected"], false);
    let warnings = planned["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("score precision")),
        "{warnings:?}"
    );
}

/// RMS of `plan`'s predicted error at the cells a localised run drove through (its ground-truth
/// positions), and the RMS error it had there.
fn predicted_and_measured(map_dir: &Path, plan_dir: &Path, loc_dir: &Path) -> (f64, f64) {
    let map = stereotag::io::load_ros_occupancy(&map_dir.join("map.yaml")).unwrap();
    let g = &map.geometry;
    let key = |x: f64, y: f64| g.cell_of(x, y);
    let mut predicted = std::collections::HashMap::new();
    let csv = std::fs::read_to_string(plan_dir.join("predicted_error.csv")).unwrap();
    for line in csv.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
        predicted.insert(key(v[0], v[1]), v[2]);
    }
    let csv = std::fs::read_to_string(loc_dir.join("localization.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (x, y, gx, gy) = (col("x_m"), col("y_m"), col("gt_x_m"), col("gt_y_m"));
    let (mut p2, mut m2, mut n) = (0.0, 0.0, 0usize);
    for line in lines {
        let v: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
        if let Some(p) = predicted.get(&key(v[gx], v[gy])) {
            p2 += p * p;
            m2 += (v[x] - v[gx]).powi(2) + (v[y] - v[gy]).powi(2);
            n += 1;
        }
    }
    assert!(n > 500, "only {n} samples on predicted cells");
    ((p2 / n as f64).sqrt(), (m2 / n as f64).sqrt())
}

/// Issue 31, item 3: the office's seed 6 without pictures, whose sonar-only graph estimates the
/// wheels' distance scale 2.4% short (the simulated wheels': 0). With the scale held at the
/// wheels', the run's echoes agree better with one another (72.2% against 70.4%), so that
/// correction is taken: offline ATE 0.151 m for the odometry's 0.734 m, the corrected map's
/// occupied precision 0.801 against the ground-truth poses' 0.820. (The rule was made on seed 5,
/// which estimated 2.6% long; along the walls' turn scale its estimated scale, 2.4% long, makes
/// the echoes agree better, and is taken: 0.162 m, 0.790 against 0.852.)
#[test]
fn a_sonar_only_survey_takes_the_wheels_distance_when_the_echoes_agree_better_with_it() {
    let report = sonar_only_report("samples/office/world.yaml", 6);
    let m = |key: &str| metric(&report, key);
    assert_eq!(m("offline.sonar_wheel_distance"), 1.0);
    assert!(m("offline.odometry_distance_scale_error").abs() < 1e-3);
    assert!(m("offline.sonar_agreement_corrected") >= m("offline.sonar_agreement_odometry") + 0.03);
    assert_holds_the_map(&report, 0.2);
}

/// `world` simulated without pictures at `seed`, surveyed: its report.
fn sonar_only_report(world: &str, seed: u64) -> Value {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let settings = SimSettings {
        seed: Some(seed),
        ..SimSettings::default()
    };
    simulate(Path::new(world), &run, settings, true);
    let out = dir.path().join("survey");
    survey_run(&run, &out);
    let report = read_report(&out);
    eprintln!("{world} seed {seed}, sonar only: {}", report["metrics"]);
    report
}

/// Issue 31, item 3's figures on a survey's `report`: the offline ATE within a third of the
/// odometry's and under `max_ate_m`, the corrected map's occupied precision within 0.1 of the
/// ground-truth-pose map's.
fn assert_holds_the_map(report: &Value, max_ate_m: f64) {
    let m = |key: &str| metric(report, key);
    let (odometry, offline) = (m("ate_m.odometry"), m("ate_m.offline"));
    assert!(
        offline <= odometry / 3.0 && offline < max_ate_m,
        "ATE {offline} for {odometry}"
    );
    let (corrected, truth) = (
        m("map_corrected.occupied_precision"),
        m("map_ground_truth.occupied_precision"),
    );
    assert!(corrected >= truth - 0.1, "map {corrected} against {truth}");
}

/// The simulated museum's hall is wider than the sonar's reach: where the robot crosses it, the
/// heading drifts with nothing to match, and the matches after it pull the run onto a bent map.
/// The walls' directions correct the headings the matches are predicted along, and give the
/// odometry's turn scale the matches are made with (issue 31, item 3; seed 2: odometry 3.01 m;
/// matches alone 0.81 m; along the walls' headings 0.19 m with a map 0.77 precise and a turn scale
/// of 0.005 for the simulated wheels' 0.010; with the walls' turn scale held 0.19 m, 0.89, against
/// the ground-truth map's 0.95).
#[test]
fn the_walls_directions_hold_a_sonar_run_across_an_empty_hall() {
    let report = sonar_only_report("samples/museum/world.yaml", 2);
    let m = &report["metrics"];
    assert!(metric(&report, "offline.sonar_matches") >= 100.0, "{m}");
    assert!(
        metric(&report, "offline.sonar_wall_directions") >= 40.0,
        "{m}"
    );
    assert_eq!(metric(&report, "offline.sonar_turns_from_walls"), 1.0);
    // The simulated wheels' base is 1% off: their turns come out 1% short.
    let turn_scale = metric(&report, "offline.odometry_turn_scale_error");
    assert!((0.005..=0.015).contains(&turn_scale), "{turn_scale}");
    assert_holds_the_map(&report, 0.3);
    // Its look-around, 2.5 m from the nearest wall, is silent (29 s, a full turn): the survey
    // says so, with the heading the wheels may lose there (4.4 degrees by the noise model).
    let silent = metric(&report, "offline.sonar_silent_start_s");
    assert!((20.0..=45.0).contains(&silent), "{silent}");
    let sigma = metric(&report, "offline.sonar_silent_start_heading_sigma_deg");
    assert!((3.0..=6.0).contains(&sigma), "{sigma}");
    let warnings = report["warnings"].to_string();
    assert!(
        warnings.contains("heard nothing for the first"),
        "{warnings}"
    );
}

/// A sonar-only run with ground truth but no world file (issue 31, items 3 and 4): the survey
/// reports the trajectories' ATE and its maps against the ground-truth-pose map, says the offline
/// pass had nothing to correct against and claims nothing (no `converged`, no odometry
/// calibration, which a later survey then refuses to take).
#[test]
fn a_sonar_only_survey_corrects_with_the_sonar_or_claims_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    simulate(
        Path::new("samples/office/world.yaml"),
        &run,
        SimSettings {
            seed: Some(3),
            ..SimSettings::default()
        },
        true,
    );
    // No world: run.yaml's reference to it dropped.
    let meta = std::fs::read_to_string(run.join("run.yaml")).unwrap();
    let without: String = meta
        .lines()
        .filter(|l| !l.starts_with("world:"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_ne!(meta, without, "run.yaml names its world");
    std::fs::write(run.join("run.yaml"), without).unwrap();
    // The sonar matched with its own older readings corrects the odometry (issue 31, item 3:
    // offline ATE at most a third of the odometry's; 0.14 on this seed).
    let corrected = dir.path().join("corrected");
    let output = survey_run(&run, &corrected);
    let m = &read_report(&corrected)["metrics"];
    eprintln!("sonar-only survey, the sonar correcting: {m}");
    let (odometry, offline) = (
        metric(&read_report(&corrected), "ate_m.odometry"),
        metric(&read_report(&corrected), "ate_m.offline"),
    );
    assert!(offline <= odometry / 3.0, "ATE {offline} for {odometry}");
    // The library gives the same scores typed: against the truth only, no world.
    assert!(output.scores.world.is_none());
    let truth = output
        .scores
        .truth
        .as_ref()
        .expect("scored against the ground truth");
    assert_eq!(truth.ate_m.offline, Some(offline));
    assert!(truth.corrected_vs_ground_truth_map.is_some());
    assert!(m["offline.sonar_matches"].as_f64().unwrap() > 100.0, "{m}");
    assert_eq!(m["offline.converged"], 1.0);
    // What it warned of: the run has no pictures; the offline pass kept its solution.
    assert!(
        output
            .warnings
            .iter()
            .any(|w| w.contains("no stereo pairs")),
        "{:?}",
        output.warnings
    );
    assert!(output.survey.offline.notes.is_empty());
    // report.json keeps the same words.
    assert_eq!(
        read_report(&corrected)["warnings"],
        serde_json::json!(output.warnings)
    );
    // Why it is kept: the echoes agree with one another better along it (0.61 -> 0.81).
    let agree = |key: &str| m[key].as_f64().unwrap();
    assert!(
        agree("offline.sonar_agreement_corrected")
            >= agree("offline.sonar_agreement_odometry") + 0.03,
        "{m}"
    );
    let raw = metric(
        &read_report(&corrected),
        "map_raw.vs_ground_truth_map.occupied_precision",
    );
    let fixed = metric(
        &read_report(&corrected),
        "map_corrected.vs_ground_truth_map.occupied_precision",
    );
    assert!(fixed > raw + 0.1, "map precision {fixed} (raw {raw})");
    // With the sonar's correction off, nothing corrects the odometry and nothing is claimed.
    let config = dir.path().join("fuse.yaml");
    std::fs::write(&config, "sonar_scan_match: false\n").unwrap();
    let request = |out, calibration_from| stereotag::workflow::survey::SurveyRequest {
        calibration_from,
        config: Some(&config),
        ..stereotag::workflow::survey::SurveyRequest::new(&run, out)
    };
    let out = dir.path().join("survey");
    // The stages a user waits through are said, though a run without pictures has no steps to
    // count: the raw map, the fusion and maps.
    struct Stages(std::sync::Mutex<Vec<String>>);
    impl stereotag::progress::Progress for Stages {
        fn start(&self, stage: &str, total: u64) {
            self.0.lock().unwrap().push(format!("{stage} {total}"));
        }
    }
    let stages = Stages(Default::default());
    let output = stereotag::workflow::survey::survey(&request(&out, None), &stages).unwrap();
    let stages = stages.0.into_inner().unwrap();
    assert!(
        stages.starts_with(&["map 0".to_string(), "fuse 0".to_string()]),
        "{stages:?}"
    );
    // The offline pass's note is kept with the survey's warnings (and so in its recording).
    let said = "the offline pass has nothing to correct the odometry against";
    assert!(output
        .survey
        .offline
        .notes
        .iter()
        .any(|n| n.starts_with(said)));
    assert!(
        output.warnings.iter().any(|w| w.starts_with(said)),
        "{:?}",
        output.warnings
    );
    let report = read_report(&out);
    let m = &report["metrics"];
    eprintln!("sonar-only survey without a world: {m}");
    for key in [
        "ate_m.odometry",
        "ate_m.offline",
        "map_corrected.vs_ground_truth_map.occupied_precision",
        "map_raw.vs_ground_truth_map.occupied_precision",
    ] {
        assert!(m[key].is_f64(), "{key} missing: {m}");
    }
    assert_eq!(m["offline.nothing_to_correct"], 1.0);
    assert!(m.get("offline.converged").is_none(), "{m}");
    assert!(
        m.get("landmarks.planned").is_none(),
        "no world, no tags planned"
    );
    let landmarks = std::fs::read_to_string(out.join("landmarks.json")).unwrap();
    let landmarks: Value = serde_json::from_str(&landmarks).unwrap();
    assert!(
        landmarks["odometry_calibration"].is_null(),
        "{}",
        landmarks["odometry_calibration"]
    );
    let later = dir.path().join("later");
    let err = stereotag::workflow::survey::survey(&request(&later, Some(&out)), &Silent)
        .unwrap_err()
        .to_string();
    assert!(err.contains("no odometry_calibration"), "{err}");
    // With no world to score the corners, `plan` says when its map is the odometry's alone: on
    // the survey that corrected nothing, and on `map --poses odometry` (1.1 m from the ground
    // truth), not on the survey the sonar corrected.
    let odometry_only = |map_dir: &Path| -> Vec<String> {
        let out = map_dir.with_extension("plan");
        plan(map_dir, &out, None, false);
        let planned: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap();
        let warnings = planned["warnings"].as_array().unwrap().iter();
        warnings
            .map(|w| w.as_str().unwrap().to_owned())
            .filter(|w| w.contains("odometry"))
            .collect()
    };
    let warned = odometry_only(&out);
    assert!(
        warned.len() == 1 && warned[0].contains("the survey corrected nothing"),
        "{warned:?}"
    );
    assert_eq!(odometry_only(&corrected), Vec::<String>::new());
    let raw_map = dir.path().join("map");
    map(&run, &raw_map, PoseSource::Odometry);
    let warned = odometry_only(&raw_map);
    assert!(
        warned.len() == 1 && warned[0].contains("placed by the run's odometry alone"),
        "{warned:?}"
    );
    assert!(
        warned[0].contains("m from the run's ground truth"),
        "{warned:?}"
    );
    // A map on the ground truth is not.
    let true_map = dir.path().join("true_map");
    map(&run, &true_map, PoseSource::GroundTruth);
    assert_eq!(odometry_only(&true_map), Vec::<String>::new());
}

/// The run's odometry moved to start at (0, 0, 0), as ROS odometry does: its frame is then not
/// the world's (the ground truth stays in the world's).
fn restart_odometry_at_origin(run: &Path) {
    let path = run.join("odometry.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_owned();
    let rows: Vec<[f64; 4]> = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|f| f.trim().parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect();
    let first = stereotag::geometry::Pose2::new(rows[0][1], rows[0][2], rows[0][3]).inverse();
    let mut out = header + "\n";
    for [t, x, y, theta] in rows {
        let p = first.compose(&stereotag::geometry::Pose2::new(x, y, theta));
        out += &format!("{t:.4},{:.6},{:.6},{:.6}\n", p.x, p.y, p.theta);
    }
    std::fs::write(&path, out).unwrap();
}

/// Issue 34's anchors: the museum (seed 1) with its odometry starting at (0, 0, 0), surveyed with
/// tags 0 and 1 anchored to 1 cm (their poses given 7 and 6 mm off): the survey is in the world's
/// frame, every other landmark within 3 cm of its tag, each anchor's residual reported; a later
/// run from the same start localises in that frame; `--origin-tag` puts tag 0 at the origin.
#[test]
fn an_anchored_survey_is_solved_in_the_anchors_frame() {
    let dir = tempfile::tempdir().unwrap();
    let world_path = Path::new("samples/museum/world.yaml");
    let run = dir.path().join("run");
    simulate(world_path, &run, SimSettings::default(), false);
    restart_odometry_at_origin(&run);
    let anchors = dir.path().join("anchors.yaml");
    std::fs::write(
        &anchors,
        "anchors:\n  - {id: 0, x_m: 0.257, y_m: 8.0, z_m: 0.45, sigma_m: 0.01}\n  \
         - {id: 1, x_m: 16.0, y_m: 0.244, z_m: 0.45, sigma_m: 0.01}\n",
    )
    .unwrap();
    let world = stereotag::io::load_world(world_path).unwrap().world;
    let survey = |out: &Path, anchoring| {
        stereotag::workflow::survey::survey(
            &stereotag::workflow::survey::SurveyRequest {
                anchors: anchoring,
                ..stereotag::workflow::survey::SurveyRequest::new(&run, out)
            },
            &Silent,
        )
        .expect("the survey runs")
    };
    let anchored = dir.path().join("anchored");
    let out = survey(
        &anchored,
        stereotag::workflow::survey::Anchoring {
            file: Some(&anchors),
            ..Default::default()
        },
    );
    let error = |l: &stereotag::fusion::Landmark| {
        let t = world.tags.iter().find(|t| t.id == l.id).unwrap();
        (l.position_m[0] - t.position_m[0]).hypot(l.position_m[1] - t.position_m[1])
    };
    let others: Vec<f64> = out
        .survey
        .landmarks
        .iter()
        .filter(|l| l.id > 1)
        .map(error)
        .collect();
    eprintln!("anchored museum: other landmarks' errors {others:.4?} m");
    assert!(others.len() >= 3, "{others:?}");
    assert!(others.iter().all(|&e| e <= 0.03), "{others:?}");
    for id in [0, 1] {
        let residual = out.metrics[&format!("anchors.tag36h11_{id}.residual_m")];
        assert!(residual < 0.02, "anchor {id}: residual {residual} m");
    }
    assert_eq!(out.metrics["anchors.seen"], 2.0);
    // In the world's frame, the survey is scored against it as usual.
    assert!(out.metrics["ate_m.offline"] <= 0.05, "{:?}", out.metrics);
    // A later run leaving from the same start (here the same run) localises in that frame.
    let loc = dir.path().join("loc");
    stereotag::workflow::localize::localize(
        &stereotag::workflow::localize::LocalizeRequest {
            survey: &anchored,
            run_dir: &run,
            out: &loc,
            world: None,
            config: None,
            detect: DetectOptions::survey(Backend::ApriltagC),
            raw_odometry: false,
            no_walls: false,
            start: Default::default(),
            force: false,
            recording: RecordingRequest::none(),
        },
        &Silent,
    )
    .unwrap();
    let localised = metric(&read_report(&loc), "ate_m.localized");
    assert!(localised <= 0.05, "localised {localised} m");

    // --origin-tag 0: tag 0 at the origin facing along x, the others where tag 0 sees them.
    let origin = survey(
        &dir.path().join("origin"),
        stereotag::workflow::survey::Anchoring {
            origin_tag: Some(stereotag::visual::tags::TagId {
                family: stereotag::visual::tags::TagFamily::Tag36h11,
                id: 0,
            }),
            ..Default::default()
        },
    );
    let tag0 = world.tags.iter().find(|t| t.id == 0).unwrap();
    let world_from_tag0 =
        stereotag::geometry::Pose2::new(tag0.position_m[0], tag0.position_m[1], tag0.yaw_rad);
    for l in &origin.survey.landmarks {
        let t = world.tags.iter().find(|t| t.id == l.id).unwrap();
        let expected = world_from_tag0
            .inverse()
            .compose(&stereotag::geometry::Pose2::new(
                t.position_m[0],
                t.position_m[1],
                0.0,
            ));
        // The frame's x axis is tag 0's surveyed facing: its error (a few tenths of a degree)
        // turns the far tags about its origin (16 m away for tag 1).
        let e = (l.position_m[0] - expected.x).hypot(l.position_m[1] - expected.y);
        let allowed = 0.01 + expected.x.hypot(expected.y) * 0.3f64.to_radians();
        eprintln!(
            "tag {} in tag 0's frame: {e:.4} m off (allowed {allowed:.3})",
            l.id
        );
        assert!(e <= allowed, "tag {} in tag 0's frame: {e} m off", l.id);
    }
    assert!(!origin.metrics.contains_key("ate_m.offline"));
}

/// Issue 34's mounting: the museum (seed 1) surveyed with the camera's mounting given 5 cm off
/// in x and y and 5 degrees off in yaw breaks the survey (most sightings gated out); with
/// `estimate_mounting` the error is found within 1 cm and 0.5 degree, reported over its sigmas,
/// the corrected rig written, and the landmarks as good as with the true mounting (within 1 cm
/// of its median error).
#[test]
fn a_wrong_mounting_is_estimated_and_corrected() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    simulate(
        Path::new("samples/museum/world.yaml"),
        &run,
        SimSettings::default(),
        false,
    );
    let survey = |out: &str, estimate_mounting| {
        let out = dir.path().join(out);
        stereotag::workflow::survey::survey(
            &stereotag::workflow::survey::SurveyRequest {
                estimate_mounting,
                ..stereotag::workflow::survey::SurveyRequest::new(&run, &out)
            },
            &Silent,
        )
        .expect("the survey runs")
    };
    let truth = survey("true_mounting", false);
    let true_median = truth.metrics["landmarks.median_error_m"];
    // The default rig's left camera: (0.1, 0.06, 0.35) m, looking ahead. Given 5 cm off in x
    // and y and turned 5 degrees.
    let meta = std::fs::read_to_string(run.join("run.yaml")).unwrap();
    let wrong = meta.replace(
        "  robot_from_left: null",
        "  robot_from_left: [0.15, 0.11, 0.35, -1.5707963267948966, 0.0, -1.4835298641951802]",
    );
    assert_ne!(wrong, meta);
    std::fs::write(run.join("run.yaml"), wrong).unwrap();
    let broken = survey("wrong_mounting", false);
    let estimated = survey("estimated", true);
    // The correction that takes the wrong mounting to the true one (the tag at m ∘ z).
    let (c, s) = ((-5f64).to_radians().cos(), (-5f64).to_radians().sin());
    let expected = [
        0.1 - (c * 0.15 - s * 0.11),
        0.06 - (s * 0.15 + c * 0.11),
        -5.0,
    ];
    let m = &estimated.metrics;
    let found = [m["mounting.x_m"], m["mounting.y_m"], m["mounting.yaw_deg"]];
    eprintln!(
        "mounting: found {found:.4?} (sigmas {:.4} m, {:.4} m, {:.3} deg), expected {expected:.4?}; \
         landmark median: true mounting {true_median:.4} m, wrong {:.4} m, estimated {:.4} m",
        m["mounting.sigma_x_m"],
        m["mounting.sigma_y_m"],
        m["mounting.sigma_yaw_deg"],
        broken.metrics["landmarks.median_error_m"],
        m["landmarks.median_error_m"]
    );
    assert!((found[0] - expected[0]).abs() <= 0.01, "{found:?}");
    assert!((found[1] - expected[1]).abs() <= 0.01, "{found:?}");
    assert!((found[2] - expected[2]).abs() <= 0.5, "{found:?}");
    assert!(broken.metrics["landmarks.median_error_m"] > 0.2);
    assert!(m["landmarks.median_error_m"] <= true_median + 0.01);
    let camchain = dir.path().join("estimated/camchain_mounting.yaml");
    let rig = stereotag::io::load_rig(&camchain).unwrap();
    let t = rig.robot_from_left.translation.vector;
    assert!(
        (t.x - 0.1).abs() <= 0.01 && (t.y - 0.06).abs() <= 0.01,
        "{t:?}"
    );
}

/// Issue 34's 3D tags: the apartment's tags at door-handle height turned about their normal,
/// leaning back on the floor and tipped down from high on a wall are surveyed in full, their
/// orientation in `landmarks.json` (roll, pitch, yaw, a quaternion and the 6x6 covariance) and in
/// the WPILib layout. Seed 1 (docs/RESULTS.md gives seeds 1-5: position median 1.6-6 mm,
/// orientation median 0.2-0.4 degrees, offline ATE 0.5-1.7 cm).
#[test]
fn tags_at_any_height_and_orientation_are_surveyed_in_full() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("apartment");
    let report = demo_of(
        Path::new("samples/apartment/world.yaml"),
        None,
        &out,
        1,
        false,
    );
    let (median, turned, ate) = (
        metric(&report, "landmarks.median_error_m"),
        metric(&report, "landmarks.median_orientation_error_deg"),
        metric(&report, "ate_m.offline"),
    );
    eprintln!("apartment seed 1: landmarks {median:.4} m, {turned:.2} deg; offline ATE {ate:.4} m");
    assert_eq!(metric(&report, "landmarks.count"), 5.0);
    assert!(median <= 0.02, "position median {median}");
    assert!(turned <= 2.0, "orientation median {turned}");
    assert!(ate <= 0.025, "offline ATE {ate}");
    let file: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("landmarks.json")).unwrap())
            .unwrap();
    let leaning = file["landmarks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["id"] == 3)
        .expect("the leaning tag is surveyed");
    let pitch = leaning["pitch_rad"].as_f64().unwrap();
    assert!(
        (pitch - 30f64.to_radians()).abs() < 2f64.to_radians(),
        "pitch {pitch}"
    );
    let cov = leaning["covariance_6x6"].as_array().unwrap();
    assert_eq!(cov.len(), 6);
    assert!(cov[4][4].as_f64().unwrap() > 0.0, "pitch variance");
    // The layout's quaternion turns x (the face's normal) up by the pitch.
    let layout: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("layout.json")).unwrap()).unwrap();
    let q = &layout["tags"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["ID"] == 3)
        .unwrap()["pose"]["rotation"]["quaternion"];
    let [w, x, y, z] = ["W", "X", "Y", "Z"].map(|k| q[k].as_f64().unwrap());
    let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let normal = q * nalgebra::Vector3::x();
    assert!((normal.z.asin() - pitch).abs() < 1e-6, "normal {normal:?}");
}

/// Issue 34's ceiling tags: the loft's four tags on the ceiling, facing down and each turned its
/// own way, seen by a camera looking 30 degrees up, are surveyed with their yaw (the heading of
/// the printed tag's top) and pitch (face down). Seed 1 (docs/RESULTS.md gives seeds 1-5).
#[test]
fn tags_on_the_ceiling_are_surveyed_with_their_orientation() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("loft");
    let rig = Path::new("calibration/rigs/upward.yaml");
    let report = demo_of(
        Path::new("samples/loft/world.yaml"),
        Some(rig),
        &out,
        1,
        false,
    );
    let (median, turned, worst, ate) = (
        metric(&report, "landmarks.median_error_m"),
        metric(&report, "landmarks.median_orientation_error_deg"),
        metric(&report, "landmarks.max_orientation_error_deg"),
        metric(&report, "ate_m.offline"),
    );
    eprintln!(
        "loft seed 1: landmarks {median:.4} m, {turned:.2} deg (largest {worst:.2}); offline ATE {ate:.4} m"
    );
    assert_eq!(metric(&report, "landmarks.count"), 4.0);
    assert!(median <= 0.02, "position median {median}");
    assert!(turned <= 2.0, "orientation median {turned}");
    assert!(worst <= 5.0, "largest orientation error {worst}");
    assert!(ate <= 0.025, "offline ATE {ate}");
    let file: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("landmarks.json")).unwrap())
            .unwrap();
    for l in file["landmarks"].as_array().unwrap() {
        let pitch = l["pitch_rad"].as_f64().unwrap();
        assert!(
            (pitch + 90f64.to_radians()).abs() < 3f64.to_radians(),
            "{l}"
        );
        assert!(l["position_m"][2].as_f64().unwrap() > 2.4, "{l}");
    }
}

/// Issue 33: a tag moved after the first loop is still caught as moved, now that a re-sighting
/// the filter's gate turns away is first tried as a loop closure. The office (seed 1) is
/// simulated; its pictures from the second half of the run on are rendered again with tag 1
/// moved 1 m along its wall; the survey reports tag 1 as moved, from where it was moved to, and
/// nothing else.
#[test]
fn a_tag_moved_after_the_first_loop_is_caught_as_moved() {
    use stereotag::render::{RenderConfig, Renderer};
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let office = Path::new("samples/office/world.yaml");
    simulate(office, &run, SimSettings::default(), false);
    let mut moved = stereotag::io::load_world(office).unwrap().world;
    let tag = moved.tags.iter_mut().find(|t| t.id == 1).unwrap();
    let was = tag.position_m;
    tag.position_m[1] += 1.0;
    let to = tag.position_m;
    let rig = stereotag::io::load_rig(&run.join("rig.yaml")).unwrap();
    let renderer = Renderer::new(&rig);
    let truth = ground_truth(&run);
    let pictures = stereotag::io::load_run(&run).unwrap().stereo;
    let half = truth.last().unwrap().t_s / 2.0;
    let mut rendered = 0;
    for (k, p) in pictures.iter().enumerate().filter(|(_, p)| p.t_s > half) {
        let pose = stereotag::geometry::pose_at(&truth, p.t_s).unwrap();
        let config = RenderConfig {
            seed: 1_000_000 + k as u64,
            ..RenderConfig::default()
        };
        let pair = renderer.render(&moved, pose, &config).unwrap();
        pair.left.save(run.join(&p.left)).unwrap();
        pair.right.save(run.join(&p.right)).unwrap();
        rendered += 1;
    }
    assert!(rendered > 100, "{rendered} pictures rendered again");
    let out = dir.path().join("survey");
    survey_run(&run, &out);
    let report = read_report(&out);
    let conflicts = report["conflicts"].as_array().unwrap();
    eprintln!(
        "moved tag: {conflicts:?}; {} loop hypotheses tested",
        metric(&report, "online.loop_tests")
    );
    assert_eq!(conflicts.len(), 1, "{conflicts:?}");
    let c = &conflicts[0];
    assert_eq!(
        (c["id"].as_u64(), c["kind"].as_str()),
        (Some(1), Some("moved"))
    );
    let seen = [
        c["seen_at_m"][0].as_f64().unwrap(),
        c["seen_at_m"][1].as_f64().unwrap(),
    ];
    let landmark = [
        c["landmark_m"][0].as_f64().unwrap(),
        c["landmark_m"][1].as_f64().unwrap(),
    ];
    assert!(
        (seen[0] - to[0]).hypot(seen[1] - to[1]) < 0.1,
        "seen at {seen:?}, moved to {to:?}"
    );
    assert!(
        (landmark[0] - was[0]).hypot(landmark[1] - was[1]) < 0.1,
        "landmark {landmark:?}"
    );
}
