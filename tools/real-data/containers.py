"""Readers for the binary containers the real-data sources come in (Python standard library
only): MATLAB 5.0 MAT-files, NumPy .npy arrays and ROS 1 bags (format 2.0) with the three ROS
message types the corpus reads (sensor_msgs/Imu, nav_msgs/Odometry, sensor_msgs/NavSatFix);
and the writer of the MCAP runs that recordings with robot hints are converted to.

Every reader raises ConvertError naming the file (`where`), and the field where known, on
malformed input. The `*_bytes` builders write the same containers; convert.py's self-test uses
them to check the readers on small inline samples.
"""

import ast
import bz2
import json
import math
import struct
import zlib


class ConvertError(Exception):
    """A malformed input: names the file, the line (1-based) and the field where known."""

    def __init__(self, where, line, field, message):
        parts = [str(where)]
        if line is not None:
            parts.append(f"line {line}")
        if field is not None:
            parts.append(f"field {field!r}")
        super().__init__(": ".join(parts) + ": " + message)


def path_length(points, min_step):
    """Length of a track over points (x, y in m) at least `min_step` m apart: noise at rest
    adds none."""
    walked, last = 0.0, points[0]
    for q in points[1:]:
        step = math.dist(q, last)
        if step >= min_step:
            walked += step
            last = q
    return walked


def room_track_truth(track, min_step, source, **details):
    """A motion-capture truth over `track` ([t_s, x, y, ...] rows in the room's frame, m) and
    its path length over steps of at least `min_step` m: the last pose's distance from the
    first, the room's heading not ours (only distances are a truth). `details` go in after
    the pose count."""
    end = [track[-1][1] - track[0][1], track[-1][2] - track[0][2]]
    truth = {
        "kind": "mocap_track",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*end),
        "end_displacement_room_m": end,
        "poses": len(track),
        **details,
        "track": track,
        "track_min_step_m": min_step,
        "source": source,
    }
    return truth, path_length([row[1:3] for row in track], min_step)


# ---------------------------------------------------------------------------------------------
# MAT-file level 5 (MATLAB 5.0 format, "MAT-File Format", MathWorks, 2013; sections 1-3):
# a 128-byte header, then data elements of (type u32, byte count u32, data padded to 8 bytes),
# a small element packing type and count in one u32; miCOMPRESSED (15) elements hold zlib
# streams of further elements; miMATRIX (14) holds array flags, dimensions, name and the real
# part. Numeric and logical arrays are decoded, and the fields of 1 x 1 structs (section 1-17:
# after the name, the field-name length as one int32, the names NUL-padded to it, then one
# unnamed miMATRIX per field), stored as "variable.field.subfield" (all this corpus needs).

MAT_TYPES = {1: "b", 2: "B", 3: "h", 4: "H", 5: "i", 6: "I", 7: "f", 9: "d", 12: "q", 13: "Q"}
MI_MATRIX, MI_COMPRESSED = 14, 15
NUMERIC_CLASSES = set(range(6, 16))
STRUCT_CLASS = 2


def _mat_elements(buf, pos, end, where):
    while pos + 8 <= end:
        kind, size = struct.unpack_from("<II", buf, pos)
        if kind >> 16:  # small data element: size in the upper half, data in the tag's 2nd word
            yield kind & 0xFFFF, buf[pos + 4 : pos + 4 + (kind >> 16)]
            pos += 8
            continue
        if pos + 8 + size > end:
            raise ConvertError(where, None, None, f"MAT element at byte {pos} runs past the end")
        yield kind, buf[pos + 8 : pos + 8 + size]
        pos += 8 + size + ((-size) % 8 if kind != MI_COMPRESSED else 0)


def _mat_struct_fields(subs, name, where):
    """(field name, miMATRIX data) of a 1 x 1 struct's elements `subs` (flags, dims, name
    first)."""
    if len(subs) < 5:
        raise ConvertError(where, None, name, "MAT struct without field names")
    width = struct.unpack_from("<i", subs[3][1])[0]
    raw = subs[4][1]
    if width <= 0:
        raise ConvertError(where, None, name, f"MAT struct field-name length {width}")
    fields = [raw[i : i + width].split(b"\0")[0].decode("latin-1") for i in range(0, len(raw), width)]
    return [(field, data) for field, (kind, data) in zip(fields, subs[5:]) if kind == MI_MATRIX]


def _mat_array(data, where, arrays, name=None):
    """Stores the numeric array in miMATRIX `data` in `arrays` ({name: (dims, values)}, values
    None where not numeric), and a 1 x 1 struct's fields under "name.field"."""
    subs = list(_mat_elements(data, 0, len(data), where))
    if len(subs) < 3:
        raise ConvertError(where, None, None, "MAT array without flags, dimensions and name")
    cls = struct.unpack_from("<I", subs[0][1])[0] & 0xFF
    dims = struct.unpack("<%di" % (len(subs[1][1]) // 4), subs[1][1])
    name = subs[2][1].decode("latin-1") if name is None else name
    if cls == STRUCT_CLASS and math.prod(dims) == 1:
        for field, sub in _mat_struct_fields(subs, name, where):
            _mat_array(sub, where, arrays, f"{name}.{field}")
        return
    arrays[name] = (dims, _mat_values(subs, cls, name, where))


def _mat_values(subs, cls, name, where):
    if cls not in NUMERIC_CLASSES or len(subs) < 4:
        return None
    kind, raw = subs[3]
    code = MAT_TYPES.get(kind)
    if code is None:
        raise ConvertError(where, None, name, f"MAT data type {kind} is not supported")
    return struct.unpack("<%d%s" % (len(raw) // struct.calcsize(code), code), raw)


def read_mat(buf, where):
    """The numeric arrays of a level-5 MAT-file: {name: (dims, column-major values)}."""
    # The header's first 116 bytes are free text (MATLAB writes "MATLAB 5.0 MAT-file", other
    # writers their own); the version (0x0100) at byte 124 is what marks a level-5 file.
    if len(buf) < 128 or struct.unpack_from("<H", buf, 124)[0] != 0x0100:
        raise ConvertError(where, None, None, "not a MATLAB 5.0 MAT-file (v7.3/HDF5 is not read)")
    if buf[126:128] != b"IM":
        raise ConvertError(where, None, None, "big-endian MAT-files are not read")
    arrays = {}

    def walk(b, pos, end):
        for kind, data in _mat_elements(b, pos, end, where):
            if kind == MI_COMPRESSED:
                try:
                    inner = zlib.decompress(data)
                except zlib.error as e:
                    raise ConvertError(where, None, None, f"corrupt compressed element: {e}")
                walk(inner, 0, len(inner))
            elif kind == MI_MATRIX:
                _mat_array(data, where, arrays)

    walk(buf, 128, len(buf))
    return arrays


def mat_matrix(arrays, name, where):
    """Array `name` as a list of rows (MAT stores columns first)."""
    if name not in arrays or arrays[name][1] is None:
        raise ConvertError(where, None, name, "numeric array missing")
    dims, values = arrays[name]
    rows, cols = dims[0], dims[1]
    return [[values[c * rows + r] for c in range(cols)] for r in range(rows)]


def mat_bytes(arrays, compress):
    """A level-5 MAT-file holding double arrays {name: (rows, cols, column-major values)}."""
    def element(kind, data):
        return struct.pack("<II", kind, len(data)) + data + b"\0" * ((-len(data)) % 8)

    body = b""
    for name, (rows, cols, values) in arrays.items():
        matrix = (element(6, struct.pack("<II", 6, 0)) + element(5, struct.pack("<ii", rows, cols))
                  + element(1, name.encode()) + element(9, struct.pack("<%dd" % len(values), *values)))
        item = element(MI_MATRIX, matrix)
        if compress:
            z = zlib.compress(item)
            item = struct.pack("<II", MI_COMPRESSED, len(z)) + z
        body += item
    header = b"MATLAB 5.0 MAT-file, self-test".ljust(116) + b"\0" * 8 + struct.pack("<H", 0x0100) + b"IM"
    return header + body


# ---------------------------------------------------------------------------------------------
# MCAP (https://mcap.dev/spec): magic, Header, then Schema, Channel and Message records
# (unchunked), DataEnd and Footer (no summary; CRCs 0, which the specification reads as "not
# computed"), magic. Messages are JSON with a JSON Schema, one of the two encodings
# tools/recording reads (its older recordings' encoding), on the topics and with the schema
# names of `mems.RawImuSample` and `mems.RobotHint` (ipc-types/src/wire.rs field names).

MCAP_MAGIC = b"\x89MCAP0\r\n"
MCAP_OP = {"header": 0x01, "footer": 0x02, "schema": 0x03, "channel": 0x04, "message": 0x05, "data_end": 0x0F}
RAW_TOPIC, HINT_TOPIC = "mems/imu/raw", "mems/robot/hint"
RAW_GYRO_VALID = 1 << 4
# Offset of every time in an MCAP written here: times start at 1 s, not 0 (0 is the stamps'
# "not set").
MCAP_T0_NS = 1_000_000_000


def _mcap_str(text):
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def _mcap_record(op, body):
    return struct.pack("<BQ", MCAP_OP[op], len(body)) + body


def _counts(value, lsb):
    return max(-32768, min(32767, round(value * lsb)))


def mcap_messages(samples, hints):
    """(log time ns, topic, JSON bytes) of the raw samples and hints in time order. Raw times
    must strictly increase in an MCAP run (tools/recording refuses a repeat): a sample whose
    time does not increase is dropped and counted."""
    out, dropped, last = [], 0, None
    for s in samples:
        ns = MCAP_T0_NS + round(s[0] * 1e9)
        if last is not None and ns <= last:
            dropped += 1
            continue
        last = ns
        msg = {"stamps": {"sample_ns": ns, "acquired_ns": ns, "calibrated_ns": 0, "odometry_ns": 0},
               "seq": 0, "accel_g": list(s[1:4]), "gyro_dps": list(s[4:7]), "temp_c": 0.0,
               "accel_counts": [_counts(v, 16384) for v in s[1:4]],
               "gyro_counts": [_counts(v, 131) for v in s[4:7]], "temp_counts": 0,
               "flags": RAW_GYRO_VALID, "lost_before": 0, "undelivered": 0}
        out.append((ns, 0, RAW_TOPIC, msg))
    for h in hints:
        ns = MCAP_T0_NS + round(h["t_s"] * 1e9)
        if ns < MCAP_T0_NS:
            continue
        msg = {"stamps": {"sample_ns": ns, "acquired_ns": ns, "calibrated_ns": 0, "odometry_ns": 0},
               "seq": 0, "forward_speed_mps": h["forward_speed_mps"],
               "forward_speed_sigma_mps": h["forward_speed_sigma_mps"], "yaw_rate_rps": 0.0,
               "yaw_rate_sigma_rps": 0.0, "flags": h["flags"], "reserved16": 0, "reserved": 0}
        out.append((ns, 1, HINT_TOPIC, msg))
    out.sort(key=lambda m: (m[0], m[1]))
    seqs = {RAW_TOPIC: 0, HINT_TOPIC: 0}
    messages = []
    for ns, _, topic, msg in out:
        msg["seq"] = seqs[topic]
        seqs[topic] += 1
        messages.append((ns, topic, json.dumps(msg, separators=(",", ":")).encode()))
    return messages, dropped


def mcap_bytes(messages):
    """An MCAP file holding `messages` ((log time ns, topic, JSON bytes)) on JSON channels."""
    schemas = {RAW_TOPIC: "mems.RawImuSample", HINT_TOPIC: "mems.RobotHint"}
    out = [MCAP_MAGIC, _mcap_record("header", _mcap_str("") + _mcap_str("tools/real-data/convert.py"))]
    ids = {}
    for i, (topic, name) in enumerate(schemas.items(), start=1):
        schema = json.dumps({"title": name, "type": "object"}).encode()
        out.append(_mcap_record("schema", struct.pack("<H", i) + _mcap_str(name) + _mcap_str("jsonschema")
                                + struct.pack("<I", len(schema)) + schema))
        out.append(_mcap_record("channel", struct.pack("<HH", i, i) + _mcap_str(topic) + _mcap_str("json")
                                + struct.pack("<I", 0)))
        ids[topic] = i
    seq = {t: 0 for t in ids}
    for ns, topic, data in messages:
        out.append(_mcap_record("message", struct.pack("<HIQQ", ids[topic], seq[topic], ns, ns) + data))
        seq[topic] += 1
    out.append(_mcap_record("data_end", struct.pack("<I", 0)))
    out.append(_mcap_record("footer", struct.pack("<QQI", 0, 0, 0)))
    out.append(MCAP_MAGIC)
    return b"".join(out)


def read_mcap_records(buf):
    """(opcode, body) of every record of an MCAP file (for the self-test)."""
    assert buf.startswith(MCAP_MAGIC) and buf.endswith(MCAP_MAGIC), "no MCAP magic"
    pos, end, records = len(MCAP_MAGIC), len(buf) - len(MCAP_MAGIC), []
    while pos < end:
        op, n = struct.unpack_from("<BQ", buf, pos)
        records.append((op, buf[pos + 9: pos + 9 + n]))
        pos += 9 + n
    assert pos == end, "records overrun the file"
    return records


# ---------------------------------------------------------------------------------------------
# NumPy .npy (numpy.lib.format, "A simple file format for NumPy arrays", NEP 1): the magic
# b"\x93NUMPY", a major and minor version byte, the header length (u16 in version 1, u32 in 2
# and 3), a header that is a Python dict literal {'descr', 'fortran_order', 'shape'}, then the
# data. Little-endian floats and integers of 2-D (or 1-D) arrays only.

NPY_MAGIC = b"\x93NUMPY"
NPY_TYPES = {"<f8": "d", "<f4": "f", "<i8": "q", "<i4": "i"}


def read_npy(buf, where):
    """A .npy array as a list of rows (a 1-D array: rows of one value), in C order whatever
    the file's order."""
    if not buf.startswith(NPY_MAGIC) or len(buf) < 10:
        raise ConvertError(where, None, None, "not a NumPy .npy file")
    major = buf[6]
    if major == 1:
        start, length = 10, struct.unpack_from("<H", buf, 8)[0]
    elif major in (2, 3):
        start, length = 12, struct.unpack_from("<I", buf, 8)[0]
    else:
        raise ConvertError(where, None, None, f".npy version {major} is not read")
    try:
        header = ast.literal_eval(buf[start : start + length].decode("latin-1"))
        descr, fortran, shape = header["descr"], header["fortran_order"], tuple(header["shape"])
    except (ValueError, SyntaxError, KeyError, TypeError) as e:
        raise ConvertError(where, None, "header", f"unreadable .npy header: {e}") from None
    code = NPY_TYPES.get(descr)
    if code is None or len(shape) not in (1, 2):
        raise ConvertError(where, None, "descr", f"{descr} of shape {shape}: only little-endian 1-D or 2-D numbers are read")
    rows, cols = shape[0], (shape[1] if len(shape) == 2 else 1)
    data = buf[start + length :]
    if len(data) < rows * cols * struct.calcsize(code):
        raise ConvertError(where, None, "shape", f"{shape} needs {rows * cols} values, the file holds fewer")
    values = struct.unpack_from("<%d%s" % (rows * cols, code), data)
    if fortran:
        return [[values[c * rows + r] for c in range(cols)] for r in range(rows)]
    return [list(values[r * cols : (r + 1) * cols]) for r in range(rows)]


def npy_bytes(rows, fortran=False):
    """A version-1 .npy file of float64 rows (C or Fortran order)."""
    cols = len(rows[0])
    header = repr({"descr": "<f8", "fortran_order": fortran, "shape": (len(rows), cols)}).encode()
    header += b" " * ((-(10 + len(header) + 1)) % 64) + b"\n"
    flat = [rows[r][c] for c in range(cols) for r in range(len(rows))] if fortran else [v for row in rows for v in row]
    return NPY_MAGIC + bytes([1, 0]) + struct.pack("<H", len(header)) + header + struct.pack("<%dd" % len(flat), *flat)


# ---------------------------------------------------------------------------------------------
# ROS 1 bag, format 2.0 (wiki.ros.org/Bags/Format/2.0): the line "#ROSBAG V2.0\n", then records
# of (header length u32, header of fields (length u32, "name=value"), data length u32, data).
# The header's `op` says what the record is: 0x02 message data (conn u32, time u32 s + u32 ns),
# 0x03 bag header, 0x04 index, 0x05 chunk (compression "none" or "bz2"; its data holds
# connection and message records), 0x06 chunk info, 0x07 connection (conn, topic; its data is
# the connection header: type, md5sum, message_definition). Messages are serialized as
# wiki.ros.org/msg describes: little-endian, strings as u32 length + bytes, fixed arrays
# without a length, time as u32 s + u32 ns.

BAG_MAGIC = b"#ROSBAG V2.0\n"
OP_MESSAGE, OP_BAG_HEADER, OP_CHUNK, OP_CONNECTION = 0x02, 0x03, 0x05, 0x07
# The message types read here and the MD5 sums of their definitions (as rosbag stores them):
# a definition that differs would be decoded wrongly, so it is refused.
ROS_TYPES = {
    "sensor_msgs/Imu": "6a62c6daae103f4ff57a132d6f95cec2",
    "nav_msgs/Odometry": "cd5e73d190d741a2f92e81eda573aca7",
    "sensor_msgs/NavSatFix": "2d3a8cd499b9b4a0249fb98fd05cfa48",
}


def _bag_fields(raw, where):
    fields, pos = {}, 0
    while pos < len(raw):
        if pos + 4 > len(raw):
            raise ConvertError(where, None, None, "truncated bag record header")
        size = struct.unpack_from("<I", raw, pos)[0]
        name, sep, value = raw[pos + 4 : pos + 4 + size].partition(b"=")
        if not sep or pos + 4 + size > len(raw):
            raise ConvertError(where, None, None, f"bag header field at byte {pos} is malformed")
        fields[name.decode("latin-1")] = value
        pos += 4 + size
    return fields


def _bag_records(buf, pos, where):
    while pos < len(buf):
        if pos + 4 > len(buf):
            raise ConvertError(where, None, None, f"bag record at byte {pos} is truncated")
        size = struct.unpack_from("<I", buf, pos)[0]
        fields = _bag_fields(buf[pos + 4 : pos + 4 + size], where)
        pos += 4 + size
        if pos + 4 > len(buf) or "op" not in fields:
            raise ConvertError(where, None, None, f"bag record ending at byte {pos} has no op or data")
        length = struct.unpack_from("<I", buf, pos)[0]
        if pos + 4 + length > len(buf):
            raise ConvertError(where, None, None, f"bag record data at byte {pos} runs past the end")
        yield fields, buf[pos + 4 : pos + 4 + length]
        pos += 4 + length


def _chunk_data(fields, data, where):
    kind = fields.get("compression", b"none").decode("latin-1")
    if kind == "none":
        return data
    if kind == "bz2":
        try:
            return bz2.decompress(data)
        except (OSError, ValueError) as e:
            raise ConvertError(where, None, "compression", f"corrupt bz2 chunk: {e}") from None
    raise ConvertError(where, None, "compression", f"{kind!r} chunks are not read (only none and bz2)")


def bag_messages(buf, where, topics):
    """(topic, ROS type, serialized message) of every message on `topics` of a ROS 1 bag, in
    file order (rosbag writes chunks in time order). A topic whose type is not in ROS_TYPES, or
    whose definition's MD5 sum differs, is refused."""
    if not buf.startswith(BAG_MAGIC):
        raise ConvertError(where, None, None, "not a ROS bag of format 2.0")
    connections = {}

    def connection(fields, data):
        conn = struct.unpack("<I", fields["conn"])[0]
        header = _bag_fields(data, where)
        topic = fields["topic"].decode("latin-1")
        kind = header.get("type", b"").decode("latin-1")
        if topic in topics and ROS_TYPES.get(kind) != header.get("md5sum", b"").decode("latin-1"):
            raise ConvertError(where, None, topic, f"type {kind or '?'} with this definition is not read")
        connections[conn] = (topic, kind)

    def walk(data):
        for fields, body in _bag_records(data, 0, where):
            op = fields["op"][0]
            if op == OP_CONNECTION:
                connection(fields, body)
            elif op == OP_MESSAGE:
                topic, kind = connections.get(struct.unpack("<I", fields["conn"])[0], (None, None))
                if topic in topics:
                    yield topic, kind, body
            elif op == OP_CHUNK:
                yield from walk(_chunk_data(fields, body, where))

    yield from walk(buf[len(BAG_MAGIC):])


class _Reader:
    """Sequential little-endian reads from a serialized ROS message."""

    def __init__(self, data, where, topic):
        self.data, self.pos, self.where, self.topic = data, 0, where, topic

    def take(self, code):
        size = struct.calcsize("<" + code)
        if self.pos + size > len(self.data):
            raise ConvertError(self.where, None, self.topic, "message shorter than its type")
        values = struct.unpack_from("<" + code, self.data, self.pos)
        self.pos += size
        return values

    def string(self):
        (size,) = self.take("I")
        self.take("%ds" % size)

    def header(self):
        """std_msgs/Header: seq, stamp (s, ns), frame_id; returns the stamp in ns."""
        _, sec, nsec = self.take("III")
        self.string()
        return sec * 1_000_000_000 + nsec


def decode_imu(data, where, topic):
    """sensor_msgs/Imu: (stamp ns, angular velocity rad/s, linear acceleration m/s^2)."""
    r = _Reader(data, where, topic)
    stamp = r.header()
    r.take("4d9d")  # orientation, its covariance
    gyro = r.take("3d")
    r.take("9d")
    accel = r.take("3d")
    return stamp, gyro, accel


def decode_odometry(data, where, topic):
    """nav_msgs/Odometry: (stamp ns, twist linear x m/s, twist angular z rad/s), both in the
    child frame (the robot's base)."""
    r = _Reader(data, where, topic)
    stamp = r.header()
    r.string()  # child_frame_id
    r.take("3d4d36d")  # pose and its covariance
    linear = r.take("3d")
    angular = r.take("3d")
    return stamp, linear[0], angular[2]


def decode_navsatfix(data, where, topic):
    """sensor_msgs/NavSatFix: (stamp ns, status (-1: no fix), latitude deg, longitude deg,
    position covariance east-east m^2)."""
    r = _Reader(data, where, topic)
    stamp = r.header()
    status, _ = r.take("bH")
    lat, lon, _ = r.take("3d")
    cov = r.take("9d")
    return stamp, status, lat, lon, cov[0]


def bag_bytes(messages, compress):
    """A ROS 1 bag (format 2.0) holding `messages` ((topic, type, stamp ns, data)) in one chunk,
    bz2-compressed if `compress`, with no index records (bag_messages reads none)."""
    def record(fields, data):
        head = _fields_blob(fields)
        return struct.pack("<I", len(head)) + head + struct.pack("<I", len(data)) + data

    conns, chunk = {}, b""
    for topic, kind, stamp, data in messages:
        if topic not in conns:
            conns[topic] = len(conns)
            header = _fields_blob({"topic": topic.encode(), "type": kind.encode(), "md5sum": ROS_TYPES[kind].encode()})
            chunk += record({"op": bytes([OP_CONNECTION]), "conn": struct.pack("<I", conns[topic]),
                             "topic": topic.encode()}, header)
        chunk += record({"op": bytes([OP_MESSAGE]), "conn": struct.pack("<I", conns[topic]),
                         "time": struct.pack("<II", stamp // 1_000_000_000, stamp % 1_000_000_000)}, data)
    kind = "bz2" if compress else "none"
    body = bz2.compress(chunk) if compress else chunk
    head = record({"op": bytes([OP_BAG_HEADER]), "index_pos": struct.pack("<Q", 0),
                   "conn_count": struct.pack("<I", len(conns)), "chunk_count": struct.pack("<I", 1)}, b"")
    return BAG_MAGIC + head + record({"op": bytes([OP_CHUNK]), "compression": kind.encode(),
                                      "size": struct.pack("<I", len(chunk))}, body)


def _fields_blob(fields):
    """Bag header fields {name: bytes} as rosbag writes them: (length u32, b"name=value")."""
    return b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v for k, v in fields.items())


def _ros_header(stamp_ns, frame):
    """A serialized std_msgs/Header (seq 0)."""
    return struct.pack("<III", 0, stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000) + struct.pack("<I", len(frame)) + frame.encode()


def imu_message(stamp_ns, gyro, accel):
    """A serialized sensor_msgs/Imu (identity orientation, zero covariances)."""
    zeros9 = struct.pack("<9d", *[0.0] * 9)
    return (_ros_header(stamp_ns, "imu_link") + struct.pack("<4d", 0.0, 0.0, 0.0, 1.0) + zeros9
            + struct.pack("<3d", *gyro) + zeros9 + struct.pack("<3d", *accel) + zeros9)


def odometry_message(stamp_ns, speed, yaw_rate):
    """A serialized nav_msgs/Odometry (zero pose, forward speed and yaw rate only)."""
    return (_ros_header(stamp_ns, "odom") + struct.pack("<I", 9) + b"base_link" + struct.pack("<43d", *[0.0] * 43)
            + struct.pack("<6d", speed, 0.0, 0.0, 0.0, 0.0, yaw_rate) + struct.pack("<36d", *[0.0] * 36))


def navsatfix_message(stamp_ns, status, lat, lon, cov_east):
    """A serialized sensor_msgs/NavSatFix (altitude 0, diagonal covariance)."""
    cov = [cov_east, 0.0, 0.0, 0.0, cov_east, 0.0, 0.0, 0.0, 4 * cov_east]
    return (_ros_header(stamp_ns, "gps") + struct.pack("<bH", status, 1) + struct.pack("<3d", lat, lon, 0.0)
            + struct.pack("<9d", *cov) + struct.pack("<B", 2))


def self_test():
    """The MAT struct, .npy and ROS bag readers on containers written here or by the builders
    above, and their errors on malformed input. Returns the names checked; raises
    AssertionError."""
    def expect_error(fn, *needles):
        try:
            fn()
        except ConvertError as e:
            assert all(n in str(e) for n in needles), (str(e), needles)
            return
        raise AssertionError("no error raised")

    # A MAT-file struct as QTM writes one: s.FrameRate and s.Body.Positions (1 x 3 x 2), a
    # char field left undecoded, a free-text header.
    def element(kind, data):
        return struct.pack("<II", kind, len(data)) + data + b"\0" * ((-len(data)) % 8)

    def matrix(cls, dims, name, *rest):
        head = element(6, struct.pack("<II", cls, 0)) + element(5, struct.pack("<%di" % len(dims), *dims)) + element(1, name)
        return element(MI_MATRIX, head + b"".join(rest))

    def fields(*names):
        return element(5, struct.pack("<i", 16)) + element(1, b"".join(n.ljust(16, b"\0") for n in names))

    body = matrix(STRUCT_CLASS, (1, 1), b"Body", fields(b"Positions"),
                  matrix(6, (1, 3, 2), b"", element(9, struct.pack("<6d", 1, 2, 3, 4, 5, 6))))
    qtm = matrix(STRUCT_CLASS, (1, 1), b"s", fields(b"Name", b"FrameRate", b"Body"), matrix(4, (1, 2), b"", element(4, b"ab")),
                 matrix(6, (1, 1), b"", element(9, struct.pack("<d", 60.0))), body)
    got = read_mat(b"QTM_ver 2.10, Level 5 MAT-file".ljust(124) + struct.pack("<H", 0x0100) + b"IM" + qtm, "q.mat")
    assert got == {"s.Name": ((1, 2), None), "s.FrameRate": ((1, 1), (60.0,)), "s.Body.Positions": ((1, 3, 2), (1.0, 2.0, 3.0, 4.0, 5.0, 6.0))}, got
    expect_error(lambda: read_mat(b"MATLAB 7.3 MAT-file".ljust(124) + struct.pack("<H", 0x0200) + b"IM", "h.mat"), "h.mat", "v7.3")

    rows = [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
    assert read_npy(npy_bytes(rows), "a.npy") == rows
    assert read_npy(npy_bytes(rows, fortran=True), "a.npy") == rows
    expect_error(lambda: read_npy(npy_bytes(rows)[:-8], "a.npy"), "a.npy", "'shape'", "fewer")
    expect_error(lambda: read_npy(b"\x93NUMPY\x01\x00\x10\x00{'descr': '>f8'}      \n", "a.npy"), "a.npy", "'header'")

    stamp = 1_500_000_000_000_000_000
    messages = [("/imu", "sensor_msgs/Imu", stamp, imu_message(stamp, (0.1, 0.2, 0.3), (0.0, 9.8, 0.5))),
                ("/odom", "nav_msgs/Odometry", stamp + 5, odometry_message(stamp + 5, 1.25, -0.5)),
                ("/fix", "sensor_msgs/NavSatFix", stamp + 9, navsatfix_message(stamp + 9, 1, 45.0, 10.0, 0.81))]
    for compress in (False, True):
        got = list(bag_messages(bag_bytes(messages, compress), "b.bag", {"/imu", "/odom", "/fix"}))
        assert [g[0] for g in got] == ["/imu", "/odom", "/fix"], got
        assert decode_imu(got[0][2], "b.bag", "/imu") == (stamp, (0.1, 0.2, 0.3), (0.0, 9.8, 0.5))
        assert decode_odometry(got[1][2], "b.bag", "/odom") == (stamp + 5, 1.25, -0.5)
        assert decode_navsatfix(got[2][2], "b.bag", "/fix") == (stamp + 9, 1, 45.0, 10.0, 0.81)
    assert not list(bag_messages(bag_bytes(messages, False), "b.bag", {"/other"}))
    expect_error(lambda: decode_imu(messages[0][3][:-100], "b.bag", "/imu"), "b.bag", "'/imu'", "shorter than its type")
    lz4 = bag_bytes(messages, False).replace(b"compression=none", b"compression=lz4!")
    expect_error(lambda: list(bag_messages(lz4, "b.bag", {"/imu"})), "b.bag", "'compression'", "'lz4!'")
    odd = bag_bytes(messages, False).replace(ROS_TYPES["sensor_msgs/Imu"].encode(), b"0" * 32)
    expect_error(lambda: list(bag_messages(odd, "b.bag", {"/imu"})), "b.bag", "'/imu'", "not read")
    expect_error(lambda: list(bag_messages(b"#ROSBAG V1.2\n", "b.bag", {"/imu"})), "b.bag", "format 2.0")
    return ["MAT v5 struct (QTM)", "npy", "ROS bag (none, bz2)"]
