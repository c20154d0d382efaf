//! Our recordings as ROS 2 messages: `mems-ros2 export RUN.mcap --out BAG.mcap` rewrites a run
//! as a ROS 2 bag in one MCAP file (profile `ros2`, CDR messages, `ros2msg` schemas), laid out
//! as rosbag2's MCAP storage writes it, so that `ros2 bag play` opens it without a
//! `metadata.yaml`; `rosbags` and `mcap-ros2-support` read it back in the tests.
//!
//! - [`msg`]: the ROS 2 message types we write and their complete definitions.
//! - [`cdr`]: a message as ROS 2 serializes it (little-endian plain CDR with its header).
//! - [`convert`]: corrected samples and odometry states as `sensor_msgs/Imu`,
//!   `nav_msgs/Odometry` and `tf2_msgs/TFMessage`: frames (REP 105), covariances from our
//!   1-sigma.
//! - [`bag`]: the ros2-profile MCAP writer.
//! - [`export`]: a run to a bag, topics and times.
//!
//! Units are ROS's and ours alike (SI); frames are stated once in [`convert`], times in
//! [`export`].

#![warn(missing_docs)]

pub mod bag;
pub mod cdr;
pub mod convert;
pub mod export;
pub mod msg;
