#!/usr/bin/env python3
"""Checks that an MCAP recording's images are what ROS 2 expects, with rosbags (pure Python,
independent of omnirow and of the `mcap` crate).

For every channel whose schema is sensor_msgs/msg/Image:
  - the channel's message encoding is `cdr` and the schema's encoding is `ros2msg`;
  - the schema text (with its dependencies) defines exactly ROS 2 Jazzy's sensor_msgs/msg/Image:
    its RIHS01 type hash equals the one rosbags computes from its Jazzy type store;
  - every message decodes as sensor_msgs/msg/Image CDR, re-encodes to the same bytes, and is a
    consistent image: a known encoding, step >= width * bytes per pixel, len(data) == step * height.
Prints one JSON line per image (stamp, frame_id, size, encoding, sha256 of the pixels, the
pixels in hex up to 4 KiB, else their first 64 bytes) and a
final {"summary": ...} line. Exit 0 when every check passes and at least --min-images images
were found, 1 otherwise (reasons on stderr), 2 on bad usage.

    check_mcap.py recording.mcap [--min-images 1]
    check_mcap.py --self-test          # writes MCAPs with rosbags and checks good and bad ones
"""

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

IMAGE = "sensor_msgs/msg/Image"
BYTES_PER_PIXEL = {
    "mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono16": 2,
    "bayer_rggb8": 1, "bayer_bggr8": 1, "bayer_gbrg8": 1, "bayer_grbg8": 1,
}
SEPARATOR = "=" * 80


def schema_types(text):
    """Type definitions from a ros2msg schema: the main type, then `MSG: pkg/Type` sections."""
    sections = text.split(SEPARATOR + "\n")
    types = get_types_from_msg(sections[0], IMAGE)
    for sec in sections[1:]:
        head, _, body = sec.partition("\n")
        if not head.startswith("MSG: "):
            raise ValueError(f"schema section without 'MSG: ' header: {head!r}")
        name = head[5:].strip()
        if "/msg/" not in name:
            name = name.replace("/", "/msg/", 1)
        types.update(get_types_from_msg(body, name))
    return types


def strip_pad(b):
    """CDR payloads may end in up to 3 bytes of zero padding."""
    b = bytes(b)
    n = 0
    while n < 3 and b and b[-1 - n] == 0 and (len(b) - n) % 4 != 0:
        n += 1
    return b[: len(b) - n]


def open_reader(path, warnings):
    """rosbags' Reader; if it cannot open the file because a non-ROS channel has a schema
    encoding it does not know (e.g. `jsonschema`), say so and retry with that channel's schema
    read as 'no definition', so the Image channels can still be checked."""
    try:
        Reader(path).open()
        return Reader(path)
    except KeyError as e:
        warnings.append(
            f"rosbags cannot open this file as it is: a channel's schema encoding {e} is not a "
            "ROS one (KeyError in rosbags); its other channels are checked with that tolerated"
        )
    from rosbags.rosbag2 import storage_mcap
    from rosbags.interfaces import MessageDefinition, MessageDefinitionFormat

    strict = storage_mcap.get_msgdef

    def tolerant(schema):
        try:
            return strict(schema)
        except KeyError:
            return MessageDefinition(MessageDefinitionFormat.NONE, "")

    storage_mcap.get_msgdef = tolerant
    return Reader(path)


def check(path, min_images):
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    want_hash = jazzy.hash_rihs01(IMAGE)
    errors = []
    warnings = []
    images = 0
    with open_reader(path, warnings) as reader:
        conns = [c for c in reader.connections if c.msgtype == IMAGE]
        for c in conns:
            enc = getattr(c.ext, "serialization_format", None)
            if enc != "cdr":
                errors.append(f"{c.topic}: message encoding {enc!r}, not 'cdr'")
            if c.msgdef.format.name != "MSG":
                errors.append(f"{c.topic}: schema encoding {c.msgdef.format.name}, not ros2msg")
                continue
            store = get_typestore(Stores.EMPTY)
            try:
                store.register(schema_types(c.msgdef.data))
                got_hash = store.hash_rihs01(IMAGE)
            except Exception as e:  # noqa: BLE001 - report any parse failure
                errors.append(f"{c.topic}: schema does not parse: {e}")
                continue
            if got_hash != want_hash:
                errors.append(f"{c.topic}: schema hash {got_hash} != Jazzy's {want_hash}")
        for c, log_time, raw in reader.messages(connections=conns):
            try:
                m = jazzy.deserialize_cdr(raw, IMAGE)
                again = jazzy.serialize_cdr(m, IMAGE)
            except Exception as e:  # noqa: BLE001
                errors.append(f"{c.topic} @ {log_time}: does not decode: {e}")
                continue
            if strip_pad(again) != strip_pad(raw):
                errors.append(f"{c.topic} @ {log_time}: re-encoding differs from the recorded bytes")
            bpp = BYTES_PER_PIXEL.get(m.encoding)
            if bpp is None:
                errors.append(f"{c.topic} @ {log_time}: unknown encoding {m.encoding!r}")
            elif m.step < m.width * bpp:
                errors.append(f"{c.topic} @ {log_time}: step {m.step} < width {m.width} x {bpp}")
            if len(m.data) != m.step * m.height:
                errors.append(
                    f"{c.topic} @ {log_time}: {len(m.data)} bytes != step {m.step} x height {m.height}"
                )
            images += 1
            print(json.dumps({
                "topic": c.topic,
                "log_time": log_time,
                "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
                "frame_id": m.header.frame_id,
                "width": m.width,
                "height": m.height,
                "encoding": m.encoding,
                "step": m.step,
                "is_bigendian": m.is_bigendian,
                "data_len": len(m.data),
                "data_sha256": hashlib.sha256(bytes(m.data)).hexdigest(),
                "data_head_hex": bytes(m.data[:64]).hex(),
                **({"data_hex": bytes(m.data).hex()} if len(m.data) <= 4096 else {}),
            }), flush=True)
    if images < min_images:
        errors.append(f"{images} image(s), expected at least {min_images}")
    print(json.dumps({"summary": {
        "images": images, "errors": errors, "warnings": warnings, "rihs01": want_hash,
    }}))
    for w in warnings:
        print(f"check_mcap.py: {path}: warning: {w}", file=sys.stderr)
    for e in errors:
        print(f"check_mcap.py: {path}: {e}", file=sys.stderr)
    return 0 if not errors else 1


def self_test():
    """rosbags writes MCAPs; a correct one passes, a wrong schema and a bad image fail."""
    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer

    jazzy = get_typestore(Stores.ROS2_JAZZY)
    Image = jazzy.types[IMAGE]
    Header = jazzy.types["std_msgs/msg/Header"]
    Time = jazzy.types["builtin_interfaces/msg/Time"]

    def write(dirpath, data_len, msgdef=None, fmt="cdr"):
        with Writer(dirpath, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            conn = w.add_connection(
                "/omnirow/image_raw", IMAGE, typestore=jazzy, msgdef=msgdef,
                rihs01="RIHS01_" + "0" * 64 if msgdef else None, serialization_format=fmt,
            )
            for i in range(3):
                m = Image(
                    header=Header(stamp=Time(sec=100 + i, nanosec=5), frame_id="cam"),
                    height=2, width=3, encoding="rgb8", is_bigendian=0, step=9,
                    data=np.arange(data_len, dtype=np.uint8),
                )
                w.write(conn, 1_000 + i, jazzy.serialize_cdr(m, IMAGE))
        return next(Path(dirpath).glob("*.mcap"))

    with tempfile.TemporaryDirectory() as tmp:
        good = write(Path(tmp) / "good", 18)
        assert check(good, 3) == 0, "a correct recording failed"
        assert check(good, 4) == 1, "--min-images was not enforced"
        assert check(write(Path(tmp) / "bad_size", 17), 1) == 1, "a truncated image passed"
        msgdef, _ = jazzy.generate_msgdef(IMAGE, ros_version=2)
        wrong = msgdef.replace("uint32 step", "uint16 step")
        assert wrong != msgdef
        assert check(write(Path(tmp) / "bad_schema", 18, msgdef=wrong), 1) == 1, "a wrong schema passed"
        assert check(write(Path(tmp) / "bad_enc", 18, fmt="json"), 1) == 1, "json encoding passed"
    print("check_mcap.py self-test: ok")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="?", type=Path)
    ap.add_argument("--min-images", type=int, default=1)
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    if args.mcap is None:
        ap.print_usage(sys.stderr)
        return 2
    return check(args.mcap, args.min_images)


if __name__ == "__main__":
    sys.exit(main())
