"""What an NBVS run reports: the travelled distance, the summary numbers and a picture of the trajectories."""

from __future__ import annotations

from typing import Any

import numpy as np

from explore.core import plt


class Reporting:
    """Part of :class:`NBVSSession`: its summary, travel and trajectory picture."""

    def save_trajectories_png(self, path: Any, title: str = "") -> None:
        """Top view: known environment, region, the executed motions (base, or sensor without a
        base), the sensor at every scan and the collisions (red crosses)."""
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        fig, ax = plt.subplots(figsize=(6.5, 6), dpi=110)
        for body in self.sim.bodies:
            lo, hi = np.asarray(body.mesh.bounds[0]), np.asarray(body.mesh.bounds[1])
            if hi[2] < 1e-3:
                continue  # the floor
            color = "tab:orange" if body.is_object else "0.6"
            ax.add_patch(plt.Rectangle(lo[:2], *(hi - lo)[:2], color=color, alpha=0.5, lw=0))
        rlo, rhi = self.region_min, self.region_max
        ax.add_patch(plt.Rectangle(rlo[:2], *(rhi - rlo)[:2], fill=False, ls="--", color="tab:green"))
        base = list(self.robot.base_dofs)
        for run in self.executions:
            if base:
                xy = run.configs[:, base[:2]]
            else:
                xy = np.array([self.robot.fk(q)[:2, 3] for q in run.configs[:: max(1, len(run.configs) // 50)]])
            ax.plot(xy[:, 0], xy[:, 1], lw=1.2, color="tab:blue", alpha=0.8)
            for event in run.collisions:
                q = event.config
                at = q[base[:2]] if base else self.robot.fk(q)[:2, 3]
                ax.plot(*at, "x", color="red", ms=10, mew=2)
        for index, pose in enumerate(self.scan_poses):
            ax.plot(*pose[:2, 3], "^", color="k", ms=6)
            ax.annotate(str(index), pose[:2, 3], textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(title or f"{len(self.executions)} motions")
        ax.legend(handles=[
            Patch(color="0.6", alpha=0.5, label="known environment"),
            Patch(color="tab:orange", alpha=0.5, label="object"),
            Patch(fill=False, ls="--", color="tab:green", label="region"),
            Line2D([], [], color="tab:blue", label="executed motion" + ("" if base else " (sensor)")),
            Line2D([], [], marker="^", color="k", ls="", label="scan (number)"),
            Line2D([], [], marker="x", color="red", ls="", mew=2, label="collision"),
        ], fontsize=8, loc="best")
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)

    def travelled_m(self) -> float:
        """Metres the base (or, without a base, the sensor) moved in all executed motions."""
        base = list(self.robot.base_dofs)
        total = 0.0
        for run in self.executions:
            xy = run.configs[:, base[:2]] if base else np.array([self.robot.fk(q)[:3, 3] for q in run.configs])
            total += float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
        return total

    def summary(self) -> dict[str, Any]:
        """Coverage per view (the first entry is the initial scan), collisions, stop reason."""
        moves = self.records[1:]
        collisions = sum(1 for r in moves if r.collided)
        return {
            "utility": self.utility_name,
            "expected": self.expected,
            "k": self.k if self.expected else 0,
            "seed": self.seed,
            "views": len(self.records),
            "coverage": [r.coverage for r in self.records],
            "final_coverage": self.records[-1].coverage if self.records else 0.0,
            "trajectories": len(moves),
            "collisions": collisions,
            "collided": collisions > 0,
            "collision_rate": collisions / max(1, len(moves)),
            "status": self.status,
            "reason": self.reason,
            "stages": [r.stages for r in moves],
            "path_lengths": [r.path_length for r in moves],
            "ess": [r.ess for r in moves],
            "plan_attempts": len(self.plan_log),
            "plan_success_rate": sum(ok for _, ok in self.plan_log) / max(1, len(self.plan_log)),
            "planning_s_median": float(np.median([t for t, _ in self.plan_log])) if self.plan_log else None,
            "planner": self.planner_name,
            "seconds_per_view": [float(sum(r.seconds.values())) for r in moves],  # wall time: choose, move, scan
            "stage_seconds": [dict(r.seconds) for r in moves],
        }
