"""Reads a ROS 2 bag (one MCAP file, no metadata.yaml) with two independent ROS 2 readers and
prints what each decoded as JSON on stdout, for tools/ros2/tests/python_readers.rs to compare
with our own reader:

- `rosbags` (AnyReader: the bag's profile checked, each type built from the `ros2msg`
  definition the bag carries, CDR decoded by rosbags);
- `mcap` with `mcap-ros2-support`'s decoder factory (its own definition parser and CDR
  decoder).

Each also checks the types the bag defines against rosbags' copy of the ROS 2 Jazzy and Humble
interfaces (field names and types, and their RIHS01 hashes).

Output: {"profile", "library", "schemas": {name: encoding}, "channels": {topic: [schema,
message encoding]}, "types": {name: rihs01}, "rosbags": {topic: {"fields": [...], "rows":
[[log_time, publish_time, value, ...], ...]}}, "mcap_ros2": the same}. A row's values follow
"fields", the message's fields flattened to dotted paths in declaration order
("header.stamp.sec", "transforms[1].child_frame_id"); arrays of numbers stay lists.

Exit status 3: a package is missing (python3 -m pip install rosbags==0.11.9
mcap-ros2-support==0.6.0).
"""

import dataclasses
import json
import sys
from pathlib import Path

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError as e:
    print(f"cannot import a ROS 2 reader: {e}", file=sys.stderr)
    sys.exit(3)


def field_names(value):
    """The message's field names in declaration order (rosbags: dataclass; mcap_ros2: slots)."""
    if dataclasses.is_dataclass(value):
        return [f.name for f in dataclasses.fields(value) if not f.name.startswith("__")]
    return list(value.__slots__)


def flatten(value, path, out):
    """Appends (path, leaf) for each leaf of a decoded message, in declaration order."""
    if isinstance(value, (bool, int, float, str)):
        out.append((path, value))
    elif hasattr(value, "tolist"):  # a numpy array of numbers
        out.append((path, value.tolist()))
    elif isinstance(value, (list, tuple)):
        if all(isinstance(v, (int, float)) for v in value):
            out.append((path, list(value)))
        else:
            for i, v in enumerate(value):
                flatten(v, f"{path}[{i}]", out)
    else:
        for name in field_names(value):
            flatten(getattr(value, name), f"{path}.{name}" if path else name, out)


def add(topics, topic, log_time, publish_time, message):
    leaves = []
    flatten(message, "", leaves)
    table = topics.setdefault(topic, {"fields": None, "rows": []})
    fields = [p for p, _ in leaves]
    # A TFMessage's length varies: its fields are those of its longest message.
    if table["fields"] is None or len(fields) > len(table["fields"]):
        table["fields"] = fields
    table["rows"].append([log_time, publish_time] + [v for _, v in leaves])


def read_rosbags(path):
    topics = {}
    with AnyReader([path]) as reader:
        for connection, log_time, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            add(topics, connection.topic, log_time, log_time, message)
    return topics


def read_mcap_ros2(path):
    topics = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            add(topics, channel.topic, message.log_time, message.publish_time, decoded)
    return topics


def check_types(schemas):
    """Each type the bag defines has the fields of the ROS 2 interfaces (rosbags' stores);
    returns their RIHS01 hashes."""
    ours = get_typestore(Stores.EMPTY)
    for name, (encoding, data) in schemas.items():
        assert encoding == "ros2msg", f"{name}: schema encoding {encoding}"
        ours.register(get_types_from_msg(data, name))
    for store in (Stores.ROS2_JAZZY, Stores.ROS2_HUMBLE):
        ros = get_typestore(store)
        for name in ours.fielddefs:
            assert ours.fielddefs[name] == ros.fielddefs[name], (
                f"{name}: {ours.fielddefs[name]} is not {store.name}'s {ros.fielddefs[name]}"
            )
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    hashes = {}
    for name in schemas:
        hashes[name] = ours.hash_rihs01(name)
        assert hashes[name] == jazzy.hash_rihs01(name), f"{name}: RIHS01 differs from Jazzy's"
    return hashes


def main():
    path = Path(sys.argv[1])
    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    schemas = {
        s.name: (s.encoding, s.data.decode()) for s in summary.schemas.values()
    }
    report = {
        "profile": header.profile,
        "library": header.library,
        "schemas": {name: encoding for name, (encoding, _) in schemas.items()},
        "channels": {
            c.topic: [summary.schemas[c.schema_id].name, c.message_encoding]
            for c in summary.channels.values()
        },
        "types": check_types(schemas),
        "rosbags": read_rosbags(path),
        "mcap_ros2": read_mcap_ros2(path),
    }
    json.dump(report, sys.stdout)


if __name__ == "__main__":
    main()
