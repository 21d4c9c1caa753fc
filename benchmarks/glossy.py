"""Returns lost on glossy bodies: each glossy body of ``--world`` (default ``tabletop_glossy``) seen
from ``--views`` directions around it (0.6 m away, 37° above its centre) by the world's depth camera
under each profile, against the same world with every body matte (``specular`` 0).

Per body and profile: the beams that meet the body, and the share of them that return, glossy and
matte (the matte share already misses the grazing, dark and shadowed returns; the difference is the
highlights and the diffuse share the dark-surface rule sees, ``worlds/README.md``, Glossy surfaces).

    .venv/bin/python benchmarks/glossy.py [--world tabletop_glossy] [--views 12] [--json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

import numpy as np

PROFILES = ("ideal", "kinect", "tof")


def returned_share(spec: Any, registry: Any, names: list[str], profile: str, views: int) -> dict[str, tuple[int, int]]:
    """(beams meeting the body, returns among them) per body ``names`` over ``views`` views of each."""
    from explore.core import look_at
    from explore.sim import Simulation

    out = {}
    with Simulation(spec, registry) as sim:
        sensor = (spec.sensor.plugin, {**spec.sensor.params, "profile": profile})
        sim.attach_plugins(registry, sensor=sensor)
        for name in names:
            index = next(i for i, b in enumerate(sim.bodies) if b.name == name)
            centre = sim.bodies[index].mesh.vertices.mean(axis=0)
            met = kept = 0
            for k, azimuth in enumerate(np.linspace(0.0, 2.0 * np.pi, views, endpoint=False)):
                eye = centre + 0.6 * np.array([0.8 * np.cos(azimuth), 0.8 * np.sin(azimuth), 0.6])
                scan = sim.sensor.acquire(sim, look_at(eye, centre), np.random.default_rng(k))
                _, body, _ = sim.raycaster.cast(scan.origins, scan.directions)
                on = body == index
                met += int(on.sum())
                kept += int((on & scan.hits).sum())
            out[name] = (met, kept)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="tabletop_glossy")
    parser.add_argument("--views", type=int, default=12)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.views < 1:
        parser.error(f"--views: must be >= 1, got {args.views}")
    from explore.core import BadInput
    from explore.runtime.isolated_runs import make_registry
    from explore.sim import load_world_spec

    try:
        glossy = load_world_spec(args.world)
    except BadInput as error:
        parser.error(f"--world: {error}")
    shares = {b.name: b.specular for b in glossy.environment + glossy.objects if b.specular > 0}
    names = list(shares)
    if not names:
        parser.error(f"--world: {args.world}: no body has specular > 0")
    registry = make_registry()
    def matte_bodies(bodies: tuple) -> tuple:
        return tuple(dataclasses.replace(b, specular=0.0) for b in bodies)

    matte = dataclasses.replace(glossy, objects=matte_bodies(glossy.objects),
                                environment=matte_bodies(glossy.environment))
    rows = []
    for profile in PROFILES:
        seen = {kind: returned_share(spec, registry, names, profile, args.views)
                for kind, spec in (("glossy", glossy), ("matte", matte))}
        for name in names:
            (met, kept_glossy), (_, kept_matte) = seen["glossy"][name], seen["matte"][name]
            rows.append({"profile": profile, "body": name, "specular": shares[name], "beams": met,
                         "returned_glossy": kept_glossy / met, "returned_matte": kept_matte / met})
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print("| profile | body | specular | beams on it | returned, glossy | returned, matte |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for r in rows:
        print(f"| {r['profile']} | {r['body']} | {r['specular']:g} | {r['beams']} | {100 * r['returned_glossy']:.1f} % "
              f"| {100 * r['returned_matte']:.1f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
