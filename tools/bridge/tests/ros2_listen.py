"""Listens to `mems-bridge ros2` as a ROS 2 node on rmw_zenoh would, with the Zenoh Python
package alone: connects to ENDPOINT, subscribes to every key of ROS domain DOMAIN, takes the
first N messages of /odom and of /imu/data, lists the domain's liveliness tokens, and writes
JSON to the file OUT for tools/bridge/tests/ros2.rs to check (a file: the test, publishing
until the listener exits, does not read a pipe meanwhile).

Each message is decoded here from the documented formats, without any ROS 2 package: the CDR
body (OMG CDR, little-endian: a 4-byte encapsulation header 00 01 00 00, then the fields in
their .msg order, each aligned to its size counted from the end of the header; a string is a
uint32 length counting its NUL, its bytes and the NUL) of nav_msgs/Odometry and
sensor_msgs/Imu, and rmw_zenoh's attachment (docs/design.md, "Publishers": int64 sequence
number, int64 source timestamp, both little-endian, one byte of GID length, the GID).

Usage: ros2_listen.py ENDPOINT DOMAIN N OUT. Exit status 3: the `eclipse-zenoh` package is missing
(python3 -m pip install eclipse-zenoh==1.10.2).
"""

import hashlib
import json
import struct
import sys
import time

try:
    import zenoh
except ImportError as e:
    print(f"cannot import zenoh: {e}", file=sys.stderr)
    sys.exit(3)


class Cdr:
    """A reader of little-endian CDR after its encapsulation header."""

    def __init__(self, data):
        assert data[:4] == b"\x00\x01\x00\x00", f"encapsulation {data[:4].hex()}"
        self.body = data[4:]
        self.at = 0

    def read(self, fmt):
        size = struct.calcsize("<" + fmt)
        self.at += -self.at % size  # alignment from the end of the header
        (value,) = struct.unpack_from("<" + fmt, self.body, self.at)
        self.at += size
        return value

    def string(self):
        n = self.read("I")
        raw = self.body[self.at : self.at + n]
        assert raw[-1:] == b"\x00", "a string ends with its NUL"
        self.at += n
        return raw[:-1].decode()

    def doubles(self, n):
        return [self.read("d") for _ in range(n)]

    def header(self):
        return {"sec": self.read("i"), "nanosec": self.read("I"), "frame_id": self.string()}

    def end(self):
        assert self.at == len(self.body), f"{len(self.body) - self.at} bytes left over"


def odometry(data):
    c = Cdr(data)
    m = {
        "header": c.header(),
        "child_frame_id": c.string(),
        "position": c.doubles(3),
        "orientation_xyzw": c.doubles(4),
        "pose_covariance": c.doubles(36),
        "linear": c.doubles(3),
        "angular": c.doubles(3),
        "twist_covariance": c.doubles(36),
    }
    c.end()
    return m


def imu(data):
    c = Cdr(data)
    m = {
        "header": c.header(),
        "orientation_xyzw": c.doubles(4),
        "orientation_covariance": c.doubles(9),
        "angular_velocity": c.doubles(3),
        "angular_velocity_covariance": c.doubles(9),
        "linear_acceleration": c.doubles(3),
        "linear_acceleration_covariance": c.doubles(9),
    }
    c.end()
    return m


def attachment(data):
    sequence, timestamp, gid_len = struct.unpack_from("<qqB", data)
    assert gid_len == 16 and len(data) == 33, f"attachment {data.hex()}"
    return {"sequence": sequence, "timestamp_ns": timestamp, "gid": data[17:].hex()}


def main():
    endpoint, domain, n, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    decoders = {"odom": odometry, "imu/data": imu}
    report = {"keys": [], "odom": [], "imu/data": [], "tokens": []}
    with zenoh.open(conf) as session:
        subscriber = session.declare_subscriber(f"{domain}/**")
        deadline = time.monotonic() + 60
        while min(len(report["odom"]), len(report["imu/data"])) < n:
            assert time.monotonic() < deadline, f"only {len(report['odom'])} /odom and {len(report['imu/data'])} /imu/data"
            sample = subscriber.try_recv()
            if sample is None:
                time.sleep(0.001)
                continue
            key = str(sample.key_expr)
            if key not in report["keys"]:
                report["keys"].append(key)
            topic = key.split("/", 1)[1].rsplit("/", 2)[0]
            if topic in decoders and len(report[topic]) < n:
                message = decoders[topic](sample.payload.to_bytes())
                message["attachment"] = attachment(sample.attachment.to_bytes())
                report[topic].append(message)
        for reply in session.liveliness().get(f"@ros2_lv/{domain}/**", timeout=10):
            token = str(reply.ok.key_expr)
            gid = hashlib.sha256(token.encode()).digest()[:16].hex()
            report["tokens"].append({"token": token, "sha256_16": gid})
    with open(out, "w") as f:
        json.dump(report, f)


if __name__ == "__main__":
    main()
