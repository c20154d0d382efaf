"""Reads a mems-odometry MCAP recording with the official Python reader (`pip install mcap`).

Every channel is JSON described by a JSON Schema, so the reader needs a JSON decoder factory
(`mcap` ships none for JSON): the one below turns each message into a dict. Prints each
topic's count and the last live odometry position with its 1-sigma.

    python3 tools/recording/python/read_recording.py run.mcap
"""

import json
import sys

from mcap.decoder import DecoderFactory
from mcap.reader import make_reader

REVISION = 1 << 2  # OdometryState.flags: republished history (ipc-types odometry_flags)


class JsonDecoderFactory(DecoderFactory):
    """Decodes channels whose message encoding is "json" into Python objects."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding == "json":
            return lambda data: json.loads(data)
        return None


def main(path):
    counts, last = {}, None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoderFactory()])
        for _schema, channel, _message, value in reader.iter_decoded_messages(log_time_order=False):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "mems/odometry/state" and not value["flags"] & REVISION:
                last = value
    for topic, n in sorted(counts.items()):
        print(f"{topic}: {n}")
    if last is not None:
        p, s = last["position_m"], last["position_sigma_m"]
        print("last position: ({:+.3f}, {:+.3f}, {:+.3f}) m +- ({:.3f}, {:.3f}, {:.3f})".format(*p, *s))


if __name__ == "__main__":
    main(sys.argv[1])
