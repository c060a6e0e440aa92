"""A tracker loop that publishes its detections to a live idmesh sensor that
extracts events (eclipse-zenoh 1.10.x; docs/guide/extracting.md).

Your tracker gives, frame after frame, where each of its tracks is and perhaps
what its classifier thinks it is. Each frame becomes one batch of `detect`
lines (trace format version 2: time, track, x, y, optional class scores,
optional identity read) sent to <prefix>/sensor/<sensor>/ingest; the sensor,
whose topology has a [sensor.extract] table, derives the mixes and
observations itself. Lines are numbered by this producer's own counter from
0; whatever the sensor does not acknowledge is sent again from the counter it
names.

Here the "tracker" replays a file of reports (JSON lines: a header, then move
and detect lines, one frame after another); put your tracker's update loop in
`frames()`.

usage: tracker.py REPORTS ENDPOINT PREFIX SENSOR [--producer ID]
prints one JSON line: frames and lines sent, accepted, refused lines, the
sensor's events.
"""

import argparse
import itertools
import json
import sys
import time

import zenoh


def frames(path):
    """Each frame of the tracker's output: its time and its detections."""
    with open(path, encoding="utf-8") as reports:
        rows = (json.loads(text) for text in reports if text.strip())
        rows = (row for row in rows if row.get("kind") in ("move", "detect"))
        for frame_time, detections in itertools.groupby(rows, key=lambda r: r["time"]):
            yield frame_time, list(detections)


def detect_line(detection):
    """One detection as a `detect` line: position, and scores or a read if any."""
    line = {"kind": "detect", "time": detection["time"], "track": detection["track"],
            "x": detection["x"], "y": detection["y"]}
    for field in ("scores", "identity", "accuracy"):
        if field in detection:
            line[field] = detection[field]
    return json.dumps(line)


def send(session, key, producer, counter, lines):
    """One batch, until the sensor answers: its acknowledgement."""
    for attempt in range(50):
        replies = session.get(f"{key}?producer={producer};counter={counter}",
                              payload="\n".join(lines), timeout=10.0)
        for reply in replies:
            if reply.ok is None:
                raise RuntimeError(reply.err.payload.to_string())
            return json.loads(reply.ok.payload.to_string())
        time.sleep(0.1 * (attempt + 1))  # no sensor answered yet: try again
    raise RuntimeError(f"no answer from {key}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("reports", "endpoint", "prefix", "sensor"):
        parser.add_argument(name)
    parser.add_argument("--producer", default="tracker-0")
    args = parser.parse_args()

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([args.endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    key = f"{args.prefix}/sensor/{args.sensor}/ingest"
    total = {"frames": 0, "sent": 0, "accepted": 0, "errors": [], "events": 0}
    counter = 0
    with zenoh.open(config) as session:
        for _, detections in frames(args.reports):
            lines = [detect_line(d) for d in detections]
            sent = counter
            while sent < counter + len(lines):
                ack = send(session, key, args.producer, sent, lines[sent - counter:])
                total["accepted"] += len(ack["accepted"])
                total["errors"] += ack["errors"]
                total["events"] = ack["events"]
                sent = ack["next"]
            counter += len(lines)
            total["frames"] += 1
            total["sent"] += len(lines)
    print(json.dumps(total))
    return 0


if __name__ == "__main__":
    sys.exit(main())
