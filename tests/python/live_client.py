"""A Foxglove WebSocket client for the tests of `run --live`. It offers one subprotocol,
--subprotocol: foxglove.websocket.v1 (the protocol's specification) or foxglove.sdk.v1 (the
Foxglove SDK's name of the same messages; the default); `run --live` answers either.

Connects to ws://ADDR (retrying until the server is up, at most --connect-timeout s), reads the
server info and the advertised channels, subscribes to the topics given, and records every
message until the server closes the connection (the run's end). Prints one JSON object: the
server info, the channels (topic -> encoding, schema name, schema encoding, schema text), per
subscribed topic its messages (log time in ns and payload text), and the time broadcasts, into
the file --out.

Modes:
  read        read to the end (the default);
  never-read  subscribe, then never read again (the server's queue for it fills);
  leave       disconnect after --leave-after messages.

With --until-k K, a reading client disconnects once every subscribed topic brought a message of
tick K or later and the time broadcasts reached the newest message's time (the server then need
not linger for it).
"""

import argparse
import asyncio
import json
import struct
import time

import websockets

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 1
TIME = 2


async def connect(url, subprotocol, timeout):
    end = time.monotonic() + timeout
    while True:
        try:
            return await websockets.connect(
                url,
                subprotocols=[subprotocol],
                max_size=None,
                open_timeout=5,
                close_timeout=1,
            )
        except (OSError, websockets.exceptions.InvalidHandshake):
            if time.monotonic() > end:
                raise
            await asyncio.sleep(0.05)


async def run(args):
    ws = await connect(f"ws://{args.addr}", args.subprotocol, args.connect_timeout)
    if ws.subprotocol != args.subprotocol:
        raise SystemExit(f"the server chose subprotocol {ws.subprotocol!r}")
    out = {"server_info": None, "channels": {}, "messages": {}, "times": []}
    by_id = {}
    subscribed = {}
    wanted = set(args.topic)
    # The server info and the advertisements come first (text frames); wait until every wanted
    # topic is advertised, at most 10 s.
    end = time.monotonic() + 10
    while not wanted <= set(out["channels"]) or out["server_info"] is None:
        left = end - time.monotonic()
        if left <= 0:
            missing = sorted(wanted - set(out["channels"]))
            raise SystemExit(f"not advertised within 10 s: {missing}")
        frame = await asyncio.wait_for(ws.recv(), timeout=left)
        if isinstance(frame, bytes):
            continue
        msg = json.loads(frame)
        if msg["op"] == "serverInfo":
            out["server_info"] = msg
        elif msg["op"] == "advertise":
            for c in msg["channels"]:
                by_id[c["id"]] = c["topic"]
                out["channels"][c["topic"]] = {
                    "encoding": c["encoding"],
                    "schemaName": c["schemaName"],
                    "schemaEncoding": c.get("schemaEncoding"),
                    "schema": c["schema"],
                }
    subs = []
    for i, topic in enumerate(sorted(wanted)):
        cid = next(k for k, v in by_id.items() if v == topic)
        subs.append({"id": i + 1, "channelId": cid})
        subscribed[i + 1] = topic
        out["messages"][topic] = []
    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
    if args.mode == "never-read":
        # Hold the connection open, reading nothing from its socket, until the server is gone
        # (a new connection is refused).
        ws.transport.pause_reading()
        host, port = args.addr.rsplit(":", 1)
        while True:
            await asyncio.sleep(0.2)
            try:
                _, w = await asyncio.open_connection(host, int(port))
                w.close()
            except OSError:
                break
        ws.transport.abort()
        write(args.out, {"mode": "never-read"})
        return
    received = 0
    # The topics still short of --until-k.
    short = set(subscribed.values())
    try:
        async for frame in ws:
            if not isinstance(frame, bytes):
                continue
            op = frame[0]
            if op == MESSAGE_DATA:
                sub, ts = struct.unpack_from("<IQ", frame, 1)
                text = frame[13:].decode()
                topic = subscribed[sub]
                out["messages"][topic].append([ts, text])
                received += 1
                if args.mode == "leave" and received >= args.leave_after:
                    await ws.close()
                    break
                if args.until_k is not None and json.loads(text).get("k", -1) >= args.until_k:
                    short.discard(topic)
                    if not short:
                        await last_times(ws, out)
                        await ws.close()
                        break
            elif op == TIME:
                (ts,) = struct.unpack_from("<Q", frame, 1)
                out["times"].append(ts)
    except websockets.exceptions.ConnectionClosedError:
        pass
    write(args.out, out)


async def last_times(ws, out):
    """Reads on, at most 10 s, until the time broadcasts caught up with the messages received.

    The server sends a time broadcast and a message on two queues of its own (control and
    data), so the time of a tick may arrive after that tick's messages; each queue keeps its
    order, so once the time of the latest message came, every earlier one did. Only time
    broadcasts are recorded here: the messages past --until-k are not.
    """
    newest = max((ts for msgs in out["messages"].values() for ts, _ in msgs), default=0)
    end = time.monotonic() + 10
    while not out["times"] or out["times"][-1] < newest:
        left = end - time.monotonic()
        if left <= 0:
            return
        try:
            frame = await asyncio.wait_for(ws.recv(), timeout=left)
        except (asyncio.TimeoutError, websockets.exceptions.ConnectionClosed):
            return
        if isinstance(frame, bytes) and frame[0] == TIME:
            (ts,) = struct.unpack_from("<Q", frame, 1)
            out["times"].append(ts)


def write(path, value):
    with open(path, "w", encoding="utf-8") as f:
        json.dump(value, f)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("addr")
    p.add_argument("--topic", action="append", default=[])
    p.add_argument("--subprotocol", choices=SUBPROTOCOLS, default=SUBPROTOCOLS[0])
    p.add_argument("--mode", choices=["read", "never-read", "leave"], default="read")
    p.add_argument("--leave-after", type=int, default=10)
    p.add_argument("--until-k", type=int, default=None)
    p.add_argument("--connect-timeout", type=float, default=60)
    p.add_argument("--out", required=True, help="where the JSON goes")
    asyncio.run(run(p.parse_args()))


if __name__ == "__main__":
    main()
