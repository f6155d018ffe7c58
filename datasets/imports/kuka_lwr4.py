"""How `kuka-lwr4@1` in the dataset archive was made: FloBaRoID's recordings of
a real KUKA LWR 4+ (github.com/kjyv/FloBaRoID, commit
e6c077ea5c09bceb49840f49e83450bb5979029b's `data/KUKA/HW/measurements_{1,2,3}.npz`,
LGPL-3.0) converted from NumPy archives to Parquet tables, one a trajectory,
each array's joint columns named `lwr_<j>_joint.<quantity>` as the robot's URDF
(`robots/kuka_lwr4/kuka_lwr4.urdf`) names its joints; `time` is the recorded
Unix time in seconds. Nothing is resampled, filtered or dropped.

    python datasets/imports/kuka_lwr4.py FLOBAROID_CHECKOUT OUT_DIR
    alnlab dataset import --name kuka-lwr4 --source ... --citation ... \
        --licence LGPL-3.0-only --licence-file robots/kuka_lwr4/LICENSE \
        OUT_DIR/measurements_1.parquet OUT_DIR/measurements_2.parquet OUT_DIR/measurements_3.parquet

(NumPy and pyarrow, as `xtask/requirements.txt` pins them.)
"""
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

QUANTITIES = {
    "positions": "position",
    "velocities": "velocity",
    "torques": "effort",
    "accelerations": "acceleration",
    "target_positions": "target_position",
    "target_velocities": "target_velocity",
    "target_accelerations": "target_acceleration",
}


def main(checkout: str, out: str) -> None:
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    for k in (1, 2, 3):
        data = np.load(Path(checkout) / f"data/KUKA/HW/measurements_{k}.npz")
        columns = {"time": data["times"]}
        for j in range(data["positions"].shape[1]):
            for array, quantity in QUANTITIES.items():
                columns[f"lwr_{j}_joint.{quantity}"] = data[array][:, j]
        pq.write_table(pa.table(columns), out_dir / f"measurements_{k}.parquet",
                       compression="zstd")


if __name__ == "__main__":
    main(*sys.argv[1:])
