"""ROS 2 tracker messages made by an encoder idmesh did not write: the
`rosbags` package serializes them to CDR and writes rosbag2 MCAP bags
without a ROS install. The tests of idmesh's ROS 2 adapter drive it.

    ros2_tracker.py bag OUT.mcap FRAMES.json   write a bag of Detection2DArray
    ros2_tracker.py publish ENDPOINT KEY FRAMES.json [--bad N]
                                               publish them over Zenoh, with
                                               rmw_zenoh's attachment, message
                                               N cut in half
    ros2_tracker.py markers ENDPOINT KEY SECONDS
                                               print one MarkerArray, decoded
    ros2_tracker.py hash                       print MarkerArray's RIHS01 hash

FRAMES.json is a list of frames `{"sec":…, "nanosec":…, "detections":
[{"id":"3","x":…,"y":…,"classes":[["red",0.8],…]},…]}`. Each command
prints one JSON line.
"""

import json
import sys
import time

import numpy
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

VISION = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\n"
        "geometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": (
        "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n"
    ),
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\n"
        "vision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox2D bbox\n"
        "string id\n"
    ),
    "vision_msgs/msg/Detection2DArray": (
        "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n"
    ),
}

TYPE = "vision_msgs/msg/Detection2DArray"


def typestore():
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in VISION.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def message(store, frame):
    t = store.types
    header = t["std_msgs/msg/Header"](
        stamp=t["builtin_interfaces/msg/Time"](sec=frame["sec"], nanosec=frame["nanosec"]),
        frame_id="camera",
    )
    detections = []
    for d in frame["detections"]:
        results = [
            t["vision_msgs/msg/ObjectHypothesisWithPose"](
                hypothesis=t["vision_msgs/msg/ObjectHypothesis"](class_id=c, score=s),
                pose=t["geometry_msgs/msg/PoseWithCovariance"](
                    pose=t["geometry_msgs/msg/Pose"](
                        position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    ),
                    covariance=numpy.zeros(36),
                ),
            )
            for c, s in d.get("classes", [])
        ]
        bbox = t["vision_msgs/msg/BoundingBox2D"](
            center=t["vision_msgs/msg/Pose2D"](
                position=t["vision_msgs/msg/Point2D"](x=d["x"], y=d["y"]), theta=0.0
            ),
            size_x=1.0,
            size_y=1.0,
        )
        detections.append(
            t["vision_msgs/msg/Detection2D"](header=header, results=results, bbox=bbox, id=d["id"])
        )
    return t[TYPE](header=header, detections=detections)


def stamp_ns(frame):
    return frame["sec"] * 1_000_000_000 + frame["nanosec"]


def write_bag(out, frames):
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore()
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/tracker/detections", TYPE, typestore=store)
        for frame in frames:
            data = store.serialize_cdr(message(store, frame), TYPE)
            writer.write(conn, stamp_ns(frame), data)
    return {"messages": len(frames)}


def attachment(seq):
    """rmw_zenoh's attachment, in Zenoh's serialization."""
    import zenoh.ext as ze

    gid = bytes(range(16))
    return ze.z_serialize(("sequence_number", ze.Int64(seq), "source_timestamp",
                           ze.Int64(time.time_ns()), "source_gid", gid))


def publish(endpoint, key, frames, bad):
    import zenoh

    store = typestore()
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    with zenoh.open(config) as session:
        publisher = session.declare_publisher(key)
        time.sleep(0.5)
        for seq, frame in enumerate(frames):
            data = bytes(store.serialize_cdr(message(store, frame), TYPE))
            if seq == bad:
                data = data[: len(data) // 2]
            publisher.put(data, attachment=attachment(seq))
            time.sleep(0.01)
        time.sleep(0.5)
    return {"published": len(frames)}


def markers(endpoint, key, seconds):
    import zenoh
    import zenoh.ext as ze

    store = get_typestore(Stores.ROS2_JAZZY)
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    with zenoh.open(config) as session:
        tokens = [str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/**", timeout=5) if r.ok]
        subscriber = session.declare_subscriber(key)
        deadline = time.time() + seconds
        while time.time() < deadline:
            sample = subscriber.try_recv()
            if sample is None:
                time.sleep(0.05)
                continue
            att = sample.attachment
            fields = ze.z_deserialize(
                tuple[str, ze.Int64, str, ze.Int64, str, bytes], att
            ) if att is not None else None
            array = store.deserialize_cdr(bytes(sample.payload.to_bytes()),
                                          "visualization_msgs/msg/MarkerArray")
            out = []
            for m in array.markers:
                out.append({
                    "ns": m.ns, "id": m.id, "type": m.type, "action": m.action,
                    "x": m.pose.position.x, "y": m.pose.position.y,
                    "r": float(m.color.r), "b": float(m.color.b), "text": m.text,
                    "frame": m.header.frame_id,
                })
            return {
                "key": str(sample.key_expr),
                "attachment": None if fields is None else {
                    "keys": [fields[0], fields[2], fields[4]],
                    "sequence_number": int(fields[1]),
                    "source_timestamp": int(fields[3]),
                    "gid_len": len(fields[5]),
                },
                "markers": out,
                "tokens": tokens,
            }
    return {"error": "no MarkerArray within %s s" % seconds}


def main(argv):
    command = argv[1]
    if command == "bag":
        with open(argv[3]) as f:
            result = write_bag(argv[2], json.load(f))
    elif command == "publish":
        with open(argv[4]) as f:
            frames = json.load(f)
        bad = int(argv[6]) if len(argv) > 6 and argv[5] == "--bad" else -1
        result = publish(argv[2], argv[3], frames, bad)
    elif command == "markers":
        result = markers(argv[2], argv[3], float(argv[4]))
    elif command == "hash":
        result = {"hash": get_typestore(Stores.ROS2_JAZZY).hash_rihs01("visualization_msgs/msg/MarkerArray")}
    else:
        raise SystemExit("unknown command " + command)
    print(json.dumps(result))


if __name__ == "__main__":
    main(sys.argv)
