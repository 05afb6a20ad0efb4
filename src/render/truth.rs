//! Ground truth of the tags in view: each tag whose corners are in front of both cameras,
//! inside both images, facing them and not hidden behind a wall.

use super::*;
use crate::camera::{Camera, StereoRig};
use crate::geometry::Pose2;
use crate::world::World;
use nalgebra::{Isometry3, Point3};

/// Ground truth of the tags visible in both cameras.
pub(super) fn truths(
    world: &World,
    paints: &[TagPaint],
    rig: &StereoRig,
    wl: &Isometry3<f64>,
    config: &RenderConfig,
) -> Vec<TagTruth> {
    let wr = wl * rig.left_from_right();
    // Every wall, for what may hide a corner (the ceiling far above: only walls occlude).
    let occluders = Scene::new(
        world.walls.iter().map(WallSpan::new).collect(),
        Vec::new(),
        Vec::new(),
        config.ceiling_m + 100.0,
    );
    let mut truth = Vec::new();
    for (tag, paint) in world.tags.iter().zip(paints) {
        let corners = paint.corners(tag.size_m);
        let see = |cam: &Camera, world_from_cam: &Isometry3<f64>| -> Option<[[f64; 2]; 4]> {
            let eye = world_from_cam.translation.vector;
            if (eye - paint.centre).dot(&paint.normal) <= 0.0 {
                return None;
            }
            let mut out = [[0.0; 2]; 4];
            for (i, c) in corners.iter().enumerate() {
                let p = world_from_cam.inverse_transform_point(&Point3::from(*c));
                let px = cam.project(&p.coords)?;
                if px.x < 0.0
                    || px.y < 0.0
                    || px.x > cam.width as f64 - 1.0
                    || px.y > cam.height as f64 - 1.0
                {
                    return None;
                }
                // Nothing nearer along the ray to the corner (pulled 1 cm towards the camera).
                let d = c - eye;
                let (t, _) = occluders.hit(&eye, &d.normalize());
                if t < d.norm() - 0.01 {
                    return None;
                }
                out[i] = [px.x, px.y];
            }
            Some(out)
        };
        let (Some(l), Some(r)) = (see(&rig.left, wl), see(&rig.right, &wr)) else {
            continue;
        };
        let c_left = wl.inverse_transform_point(&Point3::from(paint.centre));
        truth.push(TagTruth {
            id: tag.id,
            family: tag.family,
            corners_world_m: corners.map(|c| [c.x, c.y, c.z]),
            centre_world_m: [paint.centre.x, paint.centre.y, paint.centre.z],
            left_corners_px: l,
            right_corners_px: r,
            centre_in_left_m: [c_left.x, c_left.y, c_left.z],
        });
    }
    truth
}

/// The tags of a world as the renderer paints them, to find which are in view without
/// rendering.
pub struct TagVisibility<'a> {
    world: &'a World,
    paints: Vec<TagPaint>,
}

impl<'a> TagVisibility<'a> {
    /// The world's tags, ready to be looked for; fails on a tag the renderer cannot paint.
    pub fn new(world: &'a World) -> Result<Self, RenderError> {
        let paints = world
            .tags
            .iter()
            .map(tag_paint)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { world, paints })
    }

    /// The tags a robot at `world_from_robot` sees in both cameras.
    pub fn seen(
        &self,
        rig: &StereoRig,
        world_from_robot: &Pose2,
        config: &RenderConfig,
    ) -> Vec<TagTruth> {
        truths(
            self.world,
            &self.paints,
            rig,
            &world_from_left(rig, world_from_robot),
            config,
        )
    }
}

/// The tags a robot at `world_from_robot` sees in both cameras, without rendering.
pub fn visible_tags(
    world: &World,
    rig: &StereoRig,
    world_from_robot: Pose2,
    config: &RenderConfig,
) -> Result<Vec<TagTruth>, RenderError> {
    Ok(TagVisibility::new(world)?.seen(rig, &world_from_robot, config))
}
