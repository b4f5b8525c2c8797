"""Logs followed while they are written (``wmrid live``): standard input, a CSV file being appended to, an MCAP file
being written, a rosbag2 folder (MCAP storage) being recorded, and a Foxglove WebSocket server (``ws://HOST:PORT``:
``foxglove_bridge`` on a ROS 2 robot).

:mod:`~wmrid.io.live.feeds` brings the bytes as they arrive (a file read from a remembered offset, a pipe);
:mod:`~wmrid.io.live.framing` cuts them into whole units (CSV lines, JSON lines turned into CSV lines, MCAP records,
a torn last one held back until its remainder arrives); :mod:`~wmrid.io.live.decoders` turns a batch of units into
wheel samples with wmrid's own readers (the CSV assembler, the MCAP reader and its JointState, DynamicJointState,
JSON and field-path decoders); :mod:`~wmrid.io.live.follow` puts them together per kind of source and knows what
the final ``identify`` must read: the file itself when it was read to its end, else a copy of the bytes read.
:mod:`~wmrid.io.live.foxglove` is the WebSocket protocol (frames, subscriptions, and the MCAP records what arrives is
kept as) and :mod:`~wmrid.io.live.ws_source` the WebSocket source (connection, reconnection, the temporary MCAP that
the MCAP decoder and the final ``identify`` read).
"""
