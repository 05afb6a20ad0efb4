//! Diagnostic: each wall face of a survey (`walls_corrected.csv`) against a simulated run's sonar
//! placed with the run's ground-truth poses, matched as `localize` matches them. A face the
//! survey placed well has a median misfit (range measured minus range expected) near zero and
//! a narrow spread; a face the survey misplaced has its median off (and its `sigma_m`, the
//! survey's own placement sigma, should cover it); a face that clutter or a
//! wall the survey did not see echoes in front of has a long negative tail, one the beam passes
//! (the face longer than the wall) a long positive one.
//!
//! Usage: cargo run --release --example wall_misfits -- SURVEY_DIR RUN_DIR
use stereotag::fusion::{wall_misfits, SonarInput};
use stereotag::io;

/// A range whose misfit is over this is counted apart: 5 cm (2.5 sigma of a range and a wall).
const FAR_M: f64 = 0.05;

fn main() {
    if let Err(e) = run() {
        eprintln!("wall_misfits: {e}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1).map(std::path::PathBuf::from);
    let (Some(survey), Some(run_dir)) = (args.next(), args.next()) else {
        return Err("usage: wall_misfits SURVEY_DIR RUN_DIR".into());
    };
    let walls = io::load_walls_csv(&survey.join("walls_corrected.csv"))?;
    let run = io::load_run(&run_dir)?;
    let truth = run
        .ground_truth
        .as_ref()
        .ok_or("the run has no ground_truth.csv")?;
    let sonar = SonarInput {
        readings: &run.sonar,
        layout: &run.meta.robot.sonar,
        walls: &walls,
        walls_covariance: None,
    };
    let mut misfits = wall_misfits(&sonar, truth);
    println!(
        "face,normal_deg,length_m,readings,rms_m,sigma_m,ranges,median_m,p10_m,p90_m,over_5cm"
    );
    for (i, (w, m)) in walls.iter().zip(misfits.iter_mut()).enumerate() {
        m.sort_by(f64::total_cmp);
        let q = |f: f64| {
            m.get(((m.len() as f64 - 1.0) * f).round() as usize)
                .copied()
        };
        let show = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:.3}"));
        let length = (w.to_m[0] - w.from_m[0]).hypot(w.to_m[1] - w.from_m[1]);
        println!(
            "{i},{:.1},{length:.2},{},{:.3},{},{},{},{},{},{}",
            w.normal_rad.to_degrees(),
            w.readings,
            w.rms_m,
            show(w.sigma_m),
            m.len(),
            show(q(0.5)),
            show(q(0.1)),
            show(q(0.9)),
            m.iter().filter(|v| v.abs() > FAR_M).count()
        );
    }
    Ok(())
}
