use stereotag::*;
fn main() {
    let run = io::load_run(std::path::Path::new("out/run")).unwrap();
    let w = io::load_world(std::path::Path::new("samples/office/world.yaml")).unwrap();
    let gt = run.ground_truth.clone().unwrap();
    let readings = run.placed_readings(&gt);
    let mut cfg = grid::MappingConfig::default().hough;
    cfg.min_spread_deg = 0.0; cfg.threshold = 20; cfg.peak_radius_cells = 1;
    let (f, _) = hough::features_offline(&readings, 15f64.to_radians(), &cfg);
    for f in f.iter().filter(|f| w.world.vertices.iter().any(|v| (v.position.x - f.x_m).hypot(v.position.y - f.y_m) < 0.2) || f.spread_deg >= 50.0).take(40) {
        let d = w.world.vertices.iter().map(|v| (v.position.x - f.x_m).hypot(v.position.y - f.y_m)).fold(9.0, f64::min);
        println!("{:6.2} {:6.2} votes {:5} spread {:5.0} dcorner {:.2}", f.x_m, f.y_m, f.votes, f.spread_deg, d);
    }
    let sensor_hits: Vec<_> = run.sonar.iter().collect();
    let _ = sensor_hits;
    // readings whose arc passes within 10 cm of each vertex
    for v in &w.world.vertices {
        let mut n = 0; let mut near = 0;
        for r in &readings { if let Some(rg) = r.range_m { let p = r.world_from_sensor; let d = (v.position.x-p.x).hypot(v.position.y-p.y);
            let b = stereotag::geometry::wrap_angle((v.position.y-p.y).atan2(v.position.x-p.x)-p.theta).abs();
            if b < 0.27 && d < 2.1 { n += 1; if (d-rg).abs() < 0.1 { near += 1; } } } }
        println!("vertex {:?} {:?} in-cone {} echo-at-corner {}", v.position, v.kind, n, near);
    }
}
#[allow(dead_code)]
fn unused() {}
