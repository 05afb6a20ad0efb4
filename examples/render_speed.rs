//! Times rendering one stereo pair of a world (for profiling the renderer); with `--check`, then
//! counts the pixels that differ from the pictures with every wall tested for every ray, at that
//! spot and every heading in 30 degree steps:
//! `cargo run --release --example render_speed -- WORLD.yaml X Y THETA [N] [--check]`.

use std::path::Path;
use std::time::Instant;
use stereotag::geometry::Pose2;
use stereotag::render::{RenderConfig, Renderer};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 5 {
        eprintln!("usage: render_speed WORLD.yaml X Y THETA [N] [--check]");
        std::process::exit(2);
    }
    let world = stereotag::io::load_world(Path::new(&args[1])).expect("world");
    let rig = stereotag::io::load_rig(Path::new("calibration/rigs/default.yaml")).expect("rig");
    let number = |i: usize| args[i].parse::<f64>().expect("a number");
    let pose = Pose2::new(number(2), number(3), number(4));
    let n: usize = args.get(5).map_or(20, |s| s.parse().expect("a count"));
    let renderer = Renderer::new(&rig);
    let config = RenderConfig::default();
    let _ = renderer
        .render(&world.world, pose, &config)
        .expect("render");
    let start = Instant::now();
    for _ in 0..n {
        std::hint::black_box(
            renderer
                .render(&world.world, pose, &config)
                .expect("render"),
        );
    }
    let ms = start.elapsed().as_secs_f64() * 1e3 / n as f64;
    println!("{} walls: {ms:.1} ms a pair", world.world.walls.len());
    if !args.iter().any(|a| a == "--check") {
        return;
    }
    let reference = Renderer::new(&rig).with_every_wall_tested();
    for k in 0..12 {
        let pose = Pose2::new(pose.x, pose.y, pose.theta + (k as f64 * 30.0).to_radians());
        let a = renderer
            .render(&world.world, pose, &config)
            .expect("render");
        let b = reference
            .render(&world.world, pose, &config)
            .expect("render");
        let differ = |x: &image::GrayImage, y: &image::GrayImage| {
            x.as_raw()
                .iter()
                .zip(y.as_raw())
                .filter(|(p, q)| p != q)
                .count()
        };
        println!(
            "heading +{:3} deg: {} and {} pixels differ from every wall tested",
            k * 30,
            differ(&a.left, &b.left),
            differ(&a.right, &b.right)
        );
    }
}
