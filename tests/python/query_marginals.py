"""An external Zenoh client (eclipse-zenoh 1.10.x) asks a running idmesh
coordinator for the marginals and checks the JSON it gets back.

usage: query_marginals.py [ENDPOINT [PREFIX]]   (default: the demo's,
tcp/127.0.0.1:7447 and idmesh/default)
prints the parsed answer as one JSON line; exits 1 on an error reply."""

import json
import sys

import zenoh


def main() -> int:
    endpoint = sys.argv[1] if len(sys.argv) > 1 else "tcp/127.0.0.1:7447"
    prefix = sys.argv[2] if len(sys.argv) > 2 else "idmesh/default"
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session:
        for reply in session.get(f"{prefix}/query/marginals", timeout=10.0):
            if reply.ok is None:
                print(reply.err.payload.to_string(), file=sys.stderr)
                return 1
            sample = reply.ok
            answer = json.loads(sample.payload.to_string())
            answer["encoding"] = str(sample.encoding)
            print(json.dumps(answer))
            return 0
    print("no reply", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
