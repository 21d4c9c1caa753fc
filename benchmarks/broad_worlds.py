"""The broad object set (``benchmarks/broad_set.yaml``) as pedestal worlds, and a picture of
what a model misses (issue 20).

Every object stands alone on the thesis pedestal (``worlds/bunny_pedestal.yaml``): the
region is the object's footprint plus 5.5 cm around and 7 cm above it, the overview looks at
it from where the bunny's does. Coverage c_a is measured against the observable surface
(:func:`explore.mapping.observable_surface`): the object's surface points that some view on a
sphere around it, above the pedestal top, sees within the sensor's range and incidence limit,
unoccluded. The inside of a cup counts as far as such a view sees it through the opening.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

SET_FILE = Path(__file__).with_name("broad_set.yaml")
#: objects the calibration of the stop never saw (the broad set is what it was chosen on)
HELDOUT_FILE = Path(__file__).with_name("heldout_set.yaml")
FIELD_FILE = Path(__file__).with_name("field_set.yaml")  # objects neither stop rule was chosen on
PEDESTAL_TOP = 0.50
SENSORS = {
    "laser_striper": {"plugin": "laser_striper"},
    # a close-range depth camera (ideal profile): 640 x 480 over 58 deg, 0.3-1.0 m, so that at its
    # optimal distance (0.65 m) the pixels are 1.1 mm apart, finer than c_a's 3 mm
    "depth_camera": {"plugin": "depth_camera", "params": {"width": 640, "height": 480, "min_range": 0.3,
                                                          "max_range": 1.0}},
}


ENTRY_FIELDS = ("name", "source", "size", "rpy_deg", "kind")


def broad_objects(set_file: Path = SET_FILE) -> list[dict[str, Any]]:
    """The entries of ``broad_set.yaml`` (or of another set file of the same layout); ValueError naming the
    file and the field for a file that is not such a set (the values are checked when the worlds load)."""
    try:
        data = yaml.safe_load(set_file.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        raise ValueError(f"{set_file}: not a readable YAML set file ({str(error).splitlines()[0]})") from None
    entries = data.get("objects") if isinstance(data, dict) else None
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{set_file}: objects: expected a list of objects")
    for index, entry in enumerate(entries):
        missing = [key for key in ENTRY_FIELDS if not isinstance(entry, dict) or key not in entry]
        if missing:
            raise ValueError(f"{set_file}: objects[{index}]: missing {', '.join(missing)}")
        if isinstance(entry["size"], bool) or not isinstance(entry["size"], int | float):
            raise ValueError(f"{set_file}: objects[{index}].size: expected a number, got {entry['size']!r}")
    return list(entries)


def world_data(entry: dict[str, Any], sensor: str = "laser_striper") -> dict[str, Any]:
    """The world file contents for one object of the set on the pedestal."""
    size = float(entry["size"])
    half = 0.5 * size + 0.055
    target = [0.0, 0.0, PEDESTAL_TOP + 0.53 * size]
    return {
        "name": f"broad_{entry['name']}",
        "description": f"issue 20's broad set: {entry['name']} ({entry['kind']}) on the thesis pedestal",
        "environment": [{"name": "pedestal", "box": [0.10, 0.10, PEDESTAL_TOP],
                         "position": [0.0, 0.0, 0.5 * PEDESTAL_TOP]}],
        "objects": [{"name": entry["name"], "source": entry["source"], "size": size, "rpy_deg": entry["rpy_deg"],
                     "position": [0.0, 0.0], "on_top_of": "pedestal"}],
        "region": {"min": [-half, -half, PEDESTAL_TOP], "max": [half, half, PEDESTAL_TOP + size + 0.07]},
        "robot": {"plugin": "free_flyer"},
        "sensor": SENSORS[sensor],
        "overview": {"eye": [0.35, -0.25, target[2] + 0.27], "target": target},
    }


def write_worlds(directory: Path, sensor: str = "laser_striper", names: list[str] | None = None,
                 set_file: Path = SET_FILE) -> list[Path]:
    """One world file per object of the set (or of ``names``) in ``directory``; their paths."""
    if sensor not in SENSORS:
        raise ValueError(f"--sensor: {sensor!r} is not one of {', '.join(SENSORS)}")
    entries = broad_objects(set_file)
    if names:
        known = {e["name"] for e in entries}
        unknown = sorted(set(names) - known)
        if unknown:
            raise ValueError(f"--objects: {', '.join(unknown)} not in {set_file.name} "
                             f"(valid: {', '.join(sorted(known))})")
        entries = [e for e in entries if e["name"] in names]
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for entry in entries:
        path = directory / f"broad_{entry['name']}.yaml"
        path.write_text(yaml.safe_dump(world_data(entry, sensor), sort_keys=False))
        paths.append(path)
    return paths


def missing_surface_png(observable: np.ndarray, reconstructed: np.ndarray, tau: float, path: Path, title: str) -> float:
    """The observable surface from three sides, grey where the model covers it (within ``tau``)
    and red where it does not; returns c_a. The picture of a shortfall (issue 20, item 3)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from explore.mapping import covered as covered_by

    observable = np.asarray(observable, dtype=float).reshape(-1, 3)
    covered = covered_by(reconstructed, observable, tau)
    share = float(covered.mean()) if len(covered) else 0.0
    rng = np.random.default_rng(0)
    keep = rng.permutation(len(observable))[:20000]
    shown, hit = observable[keep], covered[keep]
    fig = plt.figure(figsize=(13, 4.5), dpi=100)
    for i, (elevation, azimuth, label) in enumerate([(20, -60, "front"), (20, 120, "back"), (80, -90, "top")]):
        ax = fig.add_subplot(1, 3, i + 1, projection="3d")
        ax.scatter(*shown[hit].T, s=0.4, c="0.7", depthshade=False)
        ax.scatter(*shown[~hit].T, s=1.5, c="tab:red", depthshade=False)
        ax.view_init(elevation, azimuth)
        ax.set_box_aspect(np.ptp(observable, axis=0) + 1e-6)
        ax.set_axis_off()
        ax.set_title(label)
    fig.suptitle(f"{title}\nc_a {100 * share:.1f} % of the observable surface (red: not covered within "
                 f"{1000 * tau:.0f} mm, {int((~covered).sum())} of {len(covered)} points)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return share
