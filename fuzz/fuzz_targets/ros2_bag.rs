//! A ROS 2 bag's `.mcap` file, read by `io::rosbag::Bag` with every message decoded by the CDR
//! reader of its type; an input that is not MCAP goes to every message decoder as it is.
#![no_main]

mod common;

use stereotag::io::rosbag::{cdr, Bag};

fn decode(type_name: &str, data: &[u8]) {
    match type_name {
        "sensor_msgs/msg/Image" => drop(cdr::Image::decode(data)),
        "sensor_msgs/msg/CompressedImage" => drop(cdr::CompressedImage::decode(data)),
        "sensor_msgs/msg/CameraInfo" => drop(cdr::CameraInfo::decode(data)),
        "nav_msgs/msg/Odometry" => drop(cdr::Odometry::decode(data)),
        "sensor_msgs/msg/Range" => drop(cdr::Range::decode(data)),
        "sensor_msgs/msg/LaserScan" => drop(cdr::LaserScan::decode(data)),
        "tf2_msgs/msg/TFMessage" => drop(cdr::decode_tf(data)),
        _ => {}
    }
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if !data.starts_with(b"\x89MCAP0\r\n") {
        for t in [
            "sensor_msgs/msg/Image",
            "sensor_msgs/msg/CompressedImage",
            "sensor_msgs/msg/CameraInfo",
            "nav_msgs/msg/Odometry",
            "sensor_msgs/msg/Range",
            "sensor_msgs/msg/LaserScan",
            "tf2_msgs/msg/TFMessage",
        ] {
            decode(t, data);
        }
        return;
    }
    let path = common::write("fuzz.mcap", data);
    if let Ok(bag) = Bag::open(&path) {
        let _ = bag.messages(
            |_| true,
            |m| {
                decode(&m.topic.type_name, m.data);
                Ok(())
            },
        );
    }
});
