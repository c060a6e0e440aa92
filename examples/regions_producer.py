"""Feed several idmesh sensors at once, each the events of its own region (eclipse-zenoh 1.10.x).

A deployment with several sensors has no single sequencer: each sensor takes
the events of its part of the field, and every sensor merges all of them into
one order by (time, producer, counter) (docs/design/architecture.md, "Several
sensors"). This producer plays a tracker that sees the whole field: it splits
a trace by region -- a track belongs to the sensor nearest its last position,
or to sensor (track mod S) before it has one -- and feeds each sensor from its
own thread, concurrently:

- an event goes to the sensor of its track; a mix of two tracks in different
  regions goes to both sensors (each takes it; the merge applies it once);
- counters are this producer's own across sensors (the event's line number
  in the trace's events): a sensor sees them go up, with gaps;
- each request says `time=T`, the time of the trace's next event: this sensor
  gets nothing earlier from this producer, so the merge need not wait for it;
- at the end each sensor is told `finish`.

usage: regions_producer.py EVENTS ENDPOINT PREFIX --sensor NAME@X,Y [--sensor ...]
                           [--producer ID] [--batch N]
prints one JSON line: per sensor the lines sent, accepted, duplicates and
refused lines; the events, and how many were given to two sensors.
"""

import argparse
import json
import sys
import threading
import time

import zenoh

# With a sensor that extracts, a tracker's reports (move and detect lines)
# are split the same way: each to the sensor of its track's region.
EVENTS = ("mix", "observe", "move", "identify", "detect")


def events_of(path):
    with open(path, encoding="utf-8") as trace:
        for text in trace:
            text = text.strip()
            if text:
                event = json.loads(text)
                if event.get("kind") in EVENTS:
                    yield text, event


def split(events, places):
    """Each sensor's events: (counter, text) in the trace's order."""
    where = {}

    def sensor_of(track):
        if track not in where:
            return track % len(places)
        x, y = where[track]
        return min(range(len(places)),
                   key=lambda s: (places[s][0] - x) ** 2 + (places[s][1] - y) ** 2)

    given = [[] for _ in places]
    doubled = 0
    for counter, (text, event) in enumerate(events):
        kind = event["kind"]
        if kind in ("move", "detect"):
            where[event["track"]] = (event["x"], event["y"])
            targets = {sensor_of(event["track"])}
        elif kind == "mix":
            targets = {sensor_of(event["a"]), sensor_of(event["b"])}
            doubled += len(targets) > 1
        else:
            targets = {sensor_of(event["track"])}
        for s in targets:
            given[s].append((counter, text))
    return given, doubled


def ask(session, selector, payload):
    """One request, until the sensor answers: its acknowledgement."""
    for attempt in range(50):
        replies = session.get(selector, payload=payload, timeout=10.0)
        for reply in replies:
            if reply.ok is None:
                raise RuntimeError(reply.err.payload.to_string())
            return json.loads(reply.ok.payload.to_string())
        time.sleep(0.1 * (attempt + 1))  # no sensor answered yet: try again
    raise RuntimeError(f"no answer to {selector}")


def feed(session, key, producer, mine, times, batch, report):
    """One sensor's events, in runs of consecutive counters, then finish."""
    total = {"sent": 0, "accepted": 0, "duplicates": 0, "errors": []}
    i = 0
    while i < len(mine):
        run = [mine[i]]
        while (len(run) < batch and i + len(run) < len(mine)
               and mine[i + len(run)][0] == run[-1][0] + 1):
            run.append(mine[i + len(run)])
        first, last = run[0][0], run[-1][0]
        selector = f"{key}?producer={producer};counter={first}"
        if last + 1 < len(times):
            selector += f";time={times[last + 1]!r}"
        ack = ask(session, selector, "\n".join(text for _, text in run))
        total["sent"] += len(run)
        total["accepted"] += len(ack["accepted"])
        total["duplicates"] += len(ack["duplicates"])
        total["errors"] += ack["errors"]
        i += len(run)
    ask(session, f"{key}?producer={producer};finish", "")
    report.update(total)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("events", "endpoint", "prefix"):
        parser.add_argument(name)
    parser.add_argument("--sensor", action="append", required=True,
                        help="NAME@X,Y: a sensor and where its region's centre is")
    parser.add_argument("--producer", default="tracker")
    parser.add_argument("--batch", type=int, default=50)
    args = parser.parse_args()

    names, places = [], []
    for spec in args.sensor:
        name, _, at = spec.partition("@")
        x, y = (float(v) for v in at.split(","))
        names.append(name)
        places.append((x, y))
    events = list(events_of(args.events))
    times = [event["time"] for _, event in events]
    given, doubled = split(events, places)

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([args.endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    reports = {name: {} for name in names}
    with zenoh.open(config) as session:
        threads = [
            threading.Thread(target=feed, args=(
                session, f"{args.prefix}/sensor/{name}/ingest", args.producer,
                given[s], times, args.batch, reports[name]))
            for s, name in enumerate(names)
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    if any(not report for report in reports.values()):
        print("a sensor's feed failed", file=sys.stderr)
        return 1
    print(json.dumps({"sensors": reports, "events": len(events), "doubled": doubled}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
