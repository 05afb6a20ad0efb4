//! Speed of the visual half: one 640x480 stereo pair, rendered; detected and triangulated by us
//! (left in full, right only in the epipolar band) against the C library detecting both images
//! at its defaults.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use stereotag::geometry::Pose2;
use stereotag::render::{render_pair, RenderConfig, Renderer};
use stereotag::stereo::{detect_pair, triangulate_tags, StereoConfig};
use stereotag::tags::{CDetector, DetectorConfig, TagDetector};

fn visual(c: &mut Criterion) {
    let world =
        stereotag::io::load_world(Path::new("samples/office/world.yaml")).expect("office sample");
    let rig =
        stereotag::io::load_rig(Path::new("calibration/rigs/default.yaml")).expect("default rig");
    let pose = Pose2::new(1.0, 6.3, 2.35);
    let pair = render_pair(&world.world, &rig, pose, &RenderConfig::default()).expect("render");
    let rect = rig.rectify();

    let mut group = c.benchmark_group("stereo_pair_detect");
    let mut reference = CDetector::new(DetectorConfig::default()).expect("C detector");
    group.bench_function("apriltag_c_both_images (reference)", |b| {
        b.iter(|| {
            black_box(reference.detect(&pair.left).unwrap());
            black_box(reference.detect(&pair.right).unwrap());
        })
    });
    // Ours at the C library's contrast floor, and at the survey's (`--min-contrast 30`).
    for (name, min_contrast) in [
        ("stereotag_band_and_triangulate", 5),
        ("stereotag_band_and_triangulate_min_contrast_30", 30),
    ] {
        let mut ours = CDetector::new(DetectorConfig {
            min_contrast,
            ..DetectorConfig::default()
        })
        .expect("C detector");
        group.bench_function(name, |b| {
            b.iter(|| {
                let (l, r) = detect_pair(&mut ours, &pair.left, &pair.right).unwrap();
                black_box(triangulate_tags(
                    &rig,
                    &rect,
                    &l,
                    &r,
                    Some(0.16),
                    &StereoConfig::default(),
                ))
            })
        });
    }
    group.finish();

    let mut group = c.benchmark_group("render");
    group.sample_size(10);
    // Ours: pixels no edge crosses traced with one ray; and every sample of every pixel.
    for (name, renderer) in [
        ("render_pair_640x480_4spp", Renderer::new(&rig)),
        (
            "render_pair_640x480_4spp_every_sample",
            Renderer::new(&rig).with_every_sample(),
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    renderer
                        .render(&world.world, pose, &RenderConfig::default())
                        .unwrap(),
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, visual);
criterion_main!(benches);
