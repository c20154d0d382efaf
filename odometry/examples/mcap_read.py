"""The official Python `mcap` reader's raw read rate on one recording (run by the throughput
example with --python): the raw topic's messages read (framing, zstd), then read and decoded
(protobuf with `mcap-protobuf-support`'s decoder, or `json.loads` for an older JSON recording).
Usage: python3 mcap_read.py FILE.mcap"""

import json
import sys
import time

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

RAW = "mems/imu/raw"


def read(path, decode):
    n = 0
    start, cpu = time.perf_counter(), time.process_time()
    factory, decoders = DecoderFactory(), {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(topics=[RAW]):
            if decode:
                if channel.id not in decoders:
                    decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema) or json.loads
                decoders[channel.id](message.data)
            n += 1
    return n, time.perf_counter() - start, time.process_time() - cpu


for decode, label in ((False, "python mcap read        "), (True, "python mcap read+decode ")):
    n, wall, cpu = read(sys.argv[1], decode)
    print(
        f"{label} {n / wall * 1e-6:>6.2f} M samples/s wall {n / cpu * 1e-6:>6.2f} CPU"
        f"  ({wall:.2f} s wall, {cpu:.2f} s CPU)"
    )
