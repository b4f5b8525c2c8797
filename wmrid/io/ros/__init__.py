"""What every ROS recording format shares: its contents (topics, types, JointState series), the topics and joints chosen
for the wheels, JointState decoded in batches or streamed, and signals taken from any message by field path."""
