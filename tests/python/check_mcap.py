"""Checks an MCAP file of `fdi-launch trace export RUN_DIR --format mcap` with the reference
Python reader: prints its topics and message counts, and exits non-zero when the file is
malformed (a bad record, a CRC mismatch, a message that is not JSON or does not match its
topic's schema's fields) or a topic is missing.

    python check_mcap.py RUN_DIR/export/run.mcap
"""

import json
import sys

from mcap.reader import make_reader

# Every agent of the run has these topics, with one message per joined tick at least.
PER_AGENT = [
    "state",
    "desired",
    "tracking_error",
    "measurement/clean",
    "measurement/tampered",
    "attack",
    "estimate",
    "torque/sent",
    "torque/applied",
    "delay",
    "alarm",
    "detectors",
]


def fail(msg):
    print(f"check_mcap: {msg}", file=sys.stderr)
    sys.exit(1)


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        if summary is None:
            fail(f"{path}: no summary section")
        header = reader.get_header()
        if header.profile != "fdi-mas" or not header.library.startswith("fdi-launch "):
            fail(f"{path}: header profile {header.profile!r}, library {header.library!r}")
        meta = [m for m in reader.iter_metadata() if m.name == "fdi-mas"]
        if len(meta) != 1:
            fail(f"{path}: {len(meta)} fdi-mas metadata records, 1 expected")
        agents = meta[0].metadata["agents"].split(",")
        topics = {c.topic: c for c in summary.channels.values()}
        counts = summary.statistics.channel_message_counts
        seen = {c: 0 for c in summary.channels}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            seen[channel.id] += 1
            if schema is None or schema.encoding != "jsonschema":
                fail(f"{channel.topic}: no jsonschema schema")
            if channel.message_encoding != "json":
                fail(f"{channel.topic}: message encoding {channel.message_encoding!r}")
            fields = json.loads(schema.data)["properties"].keys()
            body = json.loads(message.data)
            if set(body) != set(fields):
                fail(f"{channel.topic}: fields {sorted(body)}, schema {sorted(fields)}")
            if message.log_time != message.publish_time:
                fail(f"{channel.topic}: log time differs from publish time")
        for cid, n in seen.items():
            if counts.get(cid, 0) != n:
                fail(f"{summary.channels[cid].topic}: {n} messages read, the summary says {counts.get(cid, 0)}")
    for topic in sorted(topics):
        print(f"{topic}\t{counts.get(topics[topic].id, 0)}")
    for a in agents:
        want = [f"/agent{a}/{t}" for t in PER_AGENT]
        missing = [t for t in want if t not in topics]
        if missing:
            fail(f"{path}: missing topics {missing}")
        empty = [t for t in want if counts.get(topics[t].id, 0) == 0]
        if empty:
            fail(f"{path}: topics without messages {empty}")
    print(f"{path}: {sum(seen.values())} messages on {len(topics)} topics, {len(agents)} agents: ok")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        fail("usage: check_mcap.py FILE.mcap")
    main(sys.argv[1])
