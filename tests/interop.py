"""Standard readers must read what alnlab writes (DESIGN.md §2).

Usage: python tests/interop.py RUN_JSON

Reads every Parquet artifact named in the run record with pyarrow and every
MCAP log with the `mcap` package, decoding each /state message with the ROS 2
decoder from the schema stored in the file, and checks the decoded values
against the stride stage's pairs table; checks that /tf and /scene use
Foxglove's well-known schema names and that every scene's model is in an
`alnlab.model` metadata record. Exits non-zero on any mismatch.
"""

import json
import math
import sys

import pyarrow.parquet as pq
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(run_json: str) -> int:
    record = json.load(open(run_json))
    checked = 0
    for variant in record["variants"]:
        artifacts = variant["artifacts"]
        for role, artifact in artifacts.items():
            path = artifact["path"]
            if path.endswith(".parquet"):
                table = pq.read_table(path)
                meta = pq.read_metadata(path).metadata
                assert table.num_rows > 0, f"{path}: no rows"
                assert meta[b"alnlab.stage"], f"{path}: no provenance"
                assert json.loads(meta[b"alnlab.params"])["seed"] == record["seed"], path
                checked += 1

        # Decode every /state message with the schema stored in the file.
        frames = {}
        with open(artifacts["trajectory"]["path"], "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            assert reader.get_header().profile == "ros2"
            summary = reader.get_summary()
            schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
            assert schemas["/tf"] == "foxglove.FrameTransforms", schemas
            assert schemas["/scene"] == "foxglove.SceneUpdate", schemas
            models = [m for m in reader.iter_metadata() if m.name == "alnlab.model"]
            scenes = {c.metadata["scene"] for c in summary.channels.values() if c.topic == "/state"}
            assert {m.metadata["scene"] for m in models} == scenes, (models, scenes)
            for m in models:
                model = json.loads(m.metadata["json"])
                assert model["links"][0]["parent"] == -1 and model["conventions"]["units"] == "SI"
            tf = 0
            for _, channel, message in reader.iter_messages(topics=["/tf"]):
                transforms = json.loads(message.data)["transforms"]
                assert all(t["parent_frame_id"] == "world" for t in transforms)
                tf += 1
            assert tf > 0, "no /tf messages"
            for schema, channel, message, decoded in reader.iter_decoded_messages(topics=["/state"]):
                assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
                names = channel.metadata["variables"].split(",")
                values = {n: getattr(decoded, n.replace(".", "_").lower()) for n in names}
                assert all(math.isfinite(v) for v in values.values())
                frames[(channel.metadata["scene"], decoded.run, decoded.frame)] = values
        assert frames, "no /state messages"

        # Every pair row equals the decoded frames it was taken from.
        pairs = pq.read_table(artifacts["pairs"]["path"]).to_pylist()
        for row in pairs:
            x = frames[(row["scene"], row["run"], row["step"])]
            y = frames[(row["scene"], row["run"], row["step"] + 1)]
            for name in x:
                assert row["x." + name] == x[name], (row["step"], name)
                assert row["y." + name] == y[name], (row["step"], name)
        print(f"{variant['name']}: {len(frames)} /state messages decoded, "
              f"{len(pairs)} pair rows match, {checked} Parquet files read")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
