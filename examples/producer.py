"""Feed your own tracker's events to a running idmesh sensor (eclipse-zenoh 1.10.x).

Each event is one line of the trace format (mix, observe, move, identify; see
shared/spec/trace.md), numbered by this producer's own counter from 0. A batch
of lines is one Zenoh get on <prefix>/sensor/<sensor>/ingest?producer=ID;counter=C;
the sensor answers once the lines are in its order, naming what it accepted,
what it already had (a resend is harmless) and what it refused, with why.
Whatever is not acknowledged is sent again from the counter the sensor names.

usage: producer.py EVENTS ENDPOINT PREFIX SENSOR [--producer ID] [--batch N] [--again]
  EVENTS    a file of trace lines (a whole trace works: the header and truth lines are skipped)
  --again   send the whole history a second time at the end (it must all come back as duplicates)
prints one JSON line: lines sent, accepted, duplicates, refused lines, the sensor's events.
"""

import argparse
import json
import sys
import time

import zenoh

EVENTS = ("mix", "observe", "move", "identify")


def events_of(path):
    with open(path, encoding="utf-8") as trace:
        for text in trace:
            text = text.strip()
            if text and json.loads(text).get("kind") in EVENTS:
                yield text


def send(session, key, producer, counter, lines):
    """One batch, until the sensor answers: its acknowledgement."""
    for attempt in range(50):
        payload = "\n".join(lines)
        replies = session.get(f"{key}?producer={producer};counter={counter}",
                              payload=payload, timeout=10.0)
        for reply in replies:
            if reply.ok is None:
                raise RuntimeError(reply.err.payload.to_string())
            return json.loads(reply.ok.payload.to_string())
        time.sleep(0.1 * (attempt + 1))  # no sensor answered yet: try again
    raise RuntimeError(f"no answer from {key}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("events", "endpoint", "prefix", "sensor"):
        parser.add_argument(name)
    parser.add_argument("--producer", default="producer-0")
    parser.add_argument("--batch", type=int, default=100)
    parser.add_argument("--again", action="store_true")
    args = parser.parse_args()
    lines = list(events_of(args.events))

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([args.endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    key = f"{args.prefix}/sensor/{args.sensor}/ingest"
    total = {"sent": 0, "accepted": 0, "duplicates": 0, "errors": [], "events": 0}
    with zenoh.open(config) as session:
        for again in ([False, True] if args.again else [False]):
            history, counter = lines, 0
            while counter < len(history):
                batch = history[counter:counter + args.batch]
                ack = send(session, key, args.producer, counter, batch)
                total["sent"] += len(batch)
                total["accepted"] += len(ack["accepted"])
                total["duplicates"] += len(ack["duplicates"])
                total["errors"] += ack["errors"]
                total["events"] = ack["events"]
                # Go on from where the sensor is: past every line it took
                # or refused for what it says (sending history again, line
                # by line: the sensor has every one of them already).
                counter = counter + len(batch) if again else ack["next"]
    print(json.dumps(total))
    return 0


if __name__ == "__main__":
    sys.exit(main())
