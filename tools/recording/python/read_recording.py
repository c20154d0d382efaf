"""Reads a mems-odometry MCAP recording with the official Python reader.

    python3 -m pip install mcap==1.6.0 mcap-protobuf-support==0.6.0
    python3 tools/recording/python/read_recording.py run.mcap

Recordings are protobuf (every channel's schema is a protobuf FileDescriptorSet: ours in
package `mems`, Foxglove's named `foxglove.*`), decoded by `mcap-protobuf-support`'s decoder
factory; older recordings are JSON described by JSON Schema, for which `mcap` ships no decoder:
the JSON factory below turns each message into a dict. With both factories, every message of
either kind decodes. Prints each topic's count and the last live odometry position with its
1-sigma.
"""

import json
import sys

from mcap.decoder import DecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

REVISION = 1 << 2  # OdometryState.flags: republished history (ipc-types odometry_flags)


class JsonDecoderFactory(DecoderFactory):
    """Decodes channels whose message encoding is "json" into Python objects."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding == "json":
            return lambda data: json.loads(data)
        return None


def field(value, name):
    """A field of a decoded message: a dict's key (JSON) or a protobuf message's attribute."""
    return value[name] if isinstance(value, dict) else getattr(value, name)


def main(path):
    counts, last = {}, None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory(), JsonDecoderFactory()])
        for _schema, channel, _message, value in reader.iter_decoded_messages(log_time_order=False):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "mems/odometry/state" and not field(value, "flags") & REVISION:
                last = value
    for topic, n in sorted(counts.items()):
        print(f"{topic}: {n}")
    if last is not None:
        p, s = field(last, "position_m"), field(last, "position_sigma_m")
        print("last position: ({:+.3f}, {:+.3f}, {:+.3f}) m +- ({:.3f}, {:.3f}, {:.3f})".format(*p, *s))


if __name__ == "__main__":
    main(sys.argv[1])
