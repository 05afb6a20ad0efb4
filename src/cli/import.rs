use super::{Bars, UsageError};
use std::path::PathBuf;
use stereotag::sonar::SonarLayout;
use stereotag::workflow::import::{
    import_asl, import_bag, import_carmen, AslRequest, BagRequest, BagTopics, CarmenRequest,
};

/// Arguments of `stereotag import`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("log").required(true).args(["bag", "asl", "carmen"])))]
pub struct Import {
    /// A ROS 2 bag: its directory (metadata.yaml and .mcap files) or one .mcap file. Reads
    /// Image/CompressedImage pairs, CameraInfo, Odometry, Range, LaserScan and tf. ROS 1 bags and
    /// SQLite (.db3) bags: convert them first with `rosbags-convert --src IN --dst OUT_DIR
    /// --dst-storage mcap` (pip install rosbags).
    #[arg(long, value_name = "BAG")]
    bag: Option<PathBuf>,
    /// An ASL dataset folder (the EuRoC layout: cam0/ and cam1/ with data.csv, data/ and
    /// sensor.yaml, here or in mav0/): stereo pairs, the rig from sensor.yaml (T_BS: the camera on
    /// the body, taken as the robot), the ground truth from state_groundtruth_estimate0/. Needs
    /// --odometry. The run has no sonar.
    #[arg(long, value_name = "DIR")]
    asl: Option<PathBuf>,
    /// ASL: the odometry, a TUM file (`timestamp tx ty tz qx qy qz qw`, seconds on the pictures'
    /// clock).
    #[arg(long, value_name = "TUM")]
    odometry: Option<PathBuf>,
    /// A CARMEN log (Radish and the classic 2D SLAM data sets; `.gz` for gzip): ODOM, FLASER,
    /// RLASER and ROBOTLASER1 lines; the scans' poses of a `*-corrected` log become the ground
    /// truth. The laser becomes the run's lidar (lidar.csv), or sonar with --as-sonar.
    #[arg(long, value_name = "LOG[.gz]")]
    carmen: Option<PathBuf>,
    /// The run directory to write (run.yaml, odometry.csv, sonar.csv, stereo.csv and pictures,
    /// rig.yaml, lidar.csv for a laser, ground_truth.csv when known, and import.json: what was
    /// read).
    #[arg(long)]
    out: PathBuf,
    /// Turn the laser into this sonar ring (frontal5 or pioneer16): per scan, each sonar's
    /// reading is the nearest laser return inside its cone (no echo beyond its range). A bag's
    /// Range topics are then not read.
    #[arg(long, value_name = "LAYOUT")]
    as_sonar: Option<String>,
    /// Bag: the left camera's Image or CompressedImage topic (default: of the bag's two image
    /// topics, the one named left, infra1 or cam0).
    #[arg(long, value_name = "TOPIC")]
    left: Option<String>,
    /// Bag: the right camera's image topic (default: the one named right, infra2 or cam1).
    #[arg(long, value_name = "TOPIC")]
    right: Option<String>,
    /// Bag: the wheel odometry, nav_msgs/Odometry (default: the bag's one Odometry topic).
    #[arg(long, value_name = "TOPIC")]
    odom: Option<String>,
    /// Bag: sonar Range topics, repeatable, `*` and `?` globs (default: every Range topic, in
    /// name order; sensor k of the run is the k-th).
    #[arg(long, value_name = "TOPIC|GLOB")]
    sonar: Vec<String>,
    /// Bag: the LaserScan topic for --as-sonar (default: the bag's one LaserScan topic).
    #[arg(long, value_name = "TOPIC")]
    scan: Option<String>,
    /// Bag: a ground-truth trajectory (nav_msgs/Odometry from a simulator or motion capture):
    /// written as ground_truth.csv, and the run's frame becomes its frame.
    #[arg(long, value_name = "TOPIC")]
    ground_truth: Option<String>,
    /// Bag: the robot's tf frame, whose pose the odometry gives and on which the sensors are
    /// placed.
    #[arg(long, default_value = "base_link", value_name = "FRAME")]
    base_frame: String,
    /// Bag and ASL: left and right images further apart than this (milliseconds) are not a pair.
    #[arg(long, default_value_t = stereotag::workflow::import::bag::DEFAULT_SYNC_MS)]
    sync_ms: f64,
    /// Bag: a Kalibr camchain for the cameras instead of their CameraInfo (the mounting still
    /// from tf when it has the left camera's frame, else from the camchain).
    #[arg(long, value_name = "CAMCHAIN")]
    rig: Option<PathBuf>,
    /// Replace the output directory if it exists.
    #[arg(long)]
    force: bool,
}

impl Import {
    /// The first flag given that only a bag import reads.
    fn bag_flag(&self) -> Option<&'static str> {
        [
            ("--left", self.left.is_some()),
            ("--right", self.right.is_some()),
            ("--odom", self.odom.is_some()),
            ("--sonar", !self.sonar.is_empty()),
            ("--scan", self.scan.is_some()),
            ("--ground-truth", self.ground_truth.is_some()),
            ("--rig", self.rig.is_some()),
        ]
        .into_iter()
        .find_map(|(flag, given)| given.then_some(flag))
    }

    pub fn run(&self, quiet: bool) -> anyhow::Result<()> {
        let layout = self
            .as_sonar
            .as_deref()
            .map(|name| {
                SonarLayout::by_name(name).ok_or_else(|| {
                    UsageError(format!(
                        "--as-sonar {name}: the layouts are frontal5 and pioneer16"
                    ))
                })
            })
            .transpose()?;
        if self.odometry.is_some() && self.asl.is_none() {
            return Err(UsageError("--odometry is for --asl".into()).into());
        }
        if !(self.sync_ms.is_finite() && self.sync_ms >= 0.0) {
            return Err(UsageError(format!(
                "--sync-ms {}: give a number of milliseconds, 0 or more",
                self.sync_ms
            ))
            .into());
        }
        if let Some(dir) = &self.asl {
            if let Some(flag) = self
                .as_sonar
                .as_ref()
                .map(|_| "--as-sonar")
                .or(self.bag_flag())
            {
                return Err(UsageError(format!("{flag} is for --bag, not --asl")).into());
            }
            import_asl(
                &AslRequest {
                    asl: dir,
                    odometry: self.odometry.as_deref(),
                    out: &self.out,
                    sync_ms: self.sync_ms,
                    force: self.force,
                },
                &Bars::new(quiet),
            )?;
            return Ok(());
        }
        if let Some(log) = &self.carmen {
            if let Some(flag) = self.bag_flag() {
                return Err(UsageError(format!("{flag} is for --bag, not --carmen")).into());
            }
            import_carmen(&CarmenRequest {
                carmen: log,
                out: &self.out,
                as_sonar: layout,
                force: self.force,
            })?;
            return Ok(());
        }
        let bag = self
            .bag
            .as_deref()
            .expect("clap requires --bag or --carmen");
        import_bag(
            &BagRequest {
                bag,
                out: &self.out,
                topics: BagTopics {
                    left: self.left.clone(),
                    right: self.right.clone(),
                    odom: self.odom.clone(),
                    sonar: self.sonar.clone(),
                    scan: self.scan.clone(),
                    ground_truth: self.ground_truth.clone(),
                },
                base_frame: self.base_frame.clone(),
                sync_ms: self.sync_ms,
                rig: self.rig.as_deref(),
                as_sonar: layout,
                force: self.force,
            },
            &Bars::new(quiet),
        )?;
        Ok(())
    }
}
