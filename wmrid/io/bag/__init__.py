"""ROS 1 bags, ROS 2 sqlite3 bags and rosbag2 folders, read through rosbags."""
