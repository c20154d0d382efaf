"""Decodes an MCAP recording with the official Python `mcap` reader and each channel's schema
(protobuf through `mcap-protobuf-support`'s decoder factory; JSON Schema for older recordings),
and prints a JSON report on stdout: channels (schema name and encodings), the summary's
per-channel message counts, the metadata records, and every decoded message with its log and publish times. A
protobuf message is reported in our JSON form (every field, `null` for an unset optional,
Foxglove's timestamps as {"sec", "nsec"}) so that both encodings compare with the same values.

Exit status 3: the `mcap` or `mcap-protobuf-support` package is missing. Any schema violation
fails with the topic, the message's log time and the offending JSON path.
"""

import json
import sys

try:
    from mcap.decoder import DecoderFactory
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
except ImportError as e:
    print(f"cannot import mcap: {e}", file=sys.stderr)
    sys.exit(3)

TYPES = {
    "object": dict,
    "array": list,
    "string": str,
    "boolean": bool,
    "null": type(None),
}


def validate(value, schema, at):
    """Checks `value` against the JSON Schema keywords our schemas use."""
    types = schema.get("type")
    if types is not None:
        types = types if isinstance(types, list) else [types]
        ok = False
        for t in types:
            if t == "integer":
                ok |= isinstance(value, int) and not isinstance(value, bool)
            elif t == "number":
                ok |= isinstance(value, (int, float)) and not isinstance(value, bool)
            else:
                ok |= isinstance(value, TYPES[t])
        if not ok:
            raise ValueError(f"{at}: {value!r} is not of type {types}")
    if "enum" in schema and value not in schema["enum"]:
        raise ValueError(f"{at}: {value!r} is not one of {schema['enum']}")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if "minimum" in schema and value < schema["minimum"]:
            raise ValueError(f"{at}: {value} < minimum {schema['minimum']}")
        if "maximum" in schema and value > schema["maximum"]:
            raise ValueError(f"{at}: {value} > maximum {schema['maximum']}")
    if isinstance(value, dict):
        for name in schema.get("required", []):
            if name not in value:
                raise ValueError(f"{at}: required property {name!r} missing")
        for name, sub in schema.get("properties", {}).items():
            if name in value:
                validate(value[name], sub, f"{at}.{name}")
    if isinstance(value, list):
        if "minItems" in schema and len(value) < schema["minItems"]:
            raise ValueError(f"{at}: fewer than {schema['minItems']} items")
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            raise ValueError(f"{at}: more than {schema['maxItems']} items")
        for i, item in enumerate(value):
            validate(item, schema.get("items", {}), f"{at}[{i}]")


class JsonSchemaDecoder(DecoderFactory):
    """Decodes `json` messages whose schema is `jsonschema`, validating each against it."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding != "json" or schema is None or schema.encoding != "jsonschema":
            return None
        parsed = json.loads(schema.data)

        def decode(data):
            value = json.loads(data)
            validate(value, parsed, schema.name)
            return value

        return decode


def plain(message):
    """A decoded protobuf message as our JSON form."""
    if message.DESCRIPTOR.full_name == "google.protobuf.Timestamp":
        return {"sec": message.seconds, "nsec": message.nanos}
    out = {}
    for f in message.DESCRIPTOR.fields:
        value = getattr(message, f.name)
        # protobuf 7 dropped `label` for `is_repeated`.
        repeated = f.is_repeated if hasattr(f, "is_repeated") else f.label == f.LABEL_REPEATED
        if repeated:
            value = [plain(v) if f.message_type else v for v in value]
        elif f.has_presence and f.message_type is None and not message.HasField(f.name):
            value = None
        elif f.message_type is not None:
            value = plain(value)
        out[f.name] = value
    return out


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory(), JsonSchemaDecoder()])
        summary = reader.get_summary()
        if summary is None:
            raise SystemExit(f"{path}: no summary (the recorder did not finish the file)")
        channels = {}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            channels[channel.topic] = {
                "schema_name": schema.name,
                "schema_encoding": schema.encoding,
                "message_encoding": channel.message_encoding,
            }
        counts = {
            summary.channels[cid].topic: n
            for cid, n in summary.statistics.channel_message_counts.items()
        }
        messages = {}
        for schema, channel, message, value in reader.iter_decoded_messages(log_time_order=False):
            messages.setdefault(channel.topic, []).append(
                {
                    "log_time": message.log_time,
                    "publish_time": message.publish_time,
                    "value": value if isinstance(value, dict) else plain(value),
                }
            )
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    json.dump(
        {
            "channels": channels,
            "summary_counts": counts,
            "metadata": metadata,
            "messages": messages,
        },
        sys.stdout,
    )


if __name__ == "__main__":
    main(sys.argv[1])
