"""World Athletics 400 m standard track in the track frame.

Track frame (``CLIP_FORMAT.md``): ``x`` along the home straight in the running
direction, ``y`` to the infield (the runner's left), ``z`` up, ground ``z = 0``.
``y = 0`` is the inner edge line of lane 1 and lane line ``i`` (0..8) lies at
``y = -1.22 i``.  We put ``x = 0`` where the home straight leaves the fourth
bend, so the finish line is at ``x = 84.39``; the first bend starts there.

Dimensions: World Athletics Track and Field Facilities Manual (2019), standard
400 m track: two semicircles of inner radius 36.50 m joined by two straights
of 84.39 m, lane width 1.22 m including the 0.05 m line on its right, 8 lanes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TrackGeometry", "STANDARD_TRACK", "lane_line_y", "lane_center_y"]


def lane_line_y(index, lane_width_m=1.22):
    """Lateral position (m) of lane line ``index`` (0 = inner edge) on the straight.

    >>> float(lane_line_y(3))
    -3.66
    """
    return -lane_width_m * np.asarray(index, dtype=float)


def lane_center_y(lane, lane_width_m=1.22):
    """Lateral position (m) of the centre of 1-based ``lane``.

    Raises
    ------
    ValueError
        If ``lane`` is not a positive lane number.

    >>> float(lane_center_y(1))
    -0.61
    """
    lane = np.asarray(lane, dtype=float)
    if np.any(lane < 1):
        raise ValueError(f"lanes are numbered from 1, got {lane}")
    return -lane_width_m * (lane - 0.5)


@dataclass(frozen=True)
class TrackGeometry:
    """Geometry of a standard 400 m track as lines and arcs on the ground plane.

    Attributes
    ----------
    lane_width_m, line_width_m, straight_length_m, inner_radius_m : float
        World Athletics standard values.
    n_lanes : int
    straight_extension_m : float
        Length of the home straight before ``x = 0`` (100 m start area) and
        the run-out after the finish, both drawn as straight lanes.
    """

    lane_width_m: float = 1.22
    line_width_m: float = 0.05
    straight_length_m: float = 84.39
    inner_radius_m: float = 36.5
    n_lanes: int = 8
    straight_extension_m: float = 20.0
    runout_m: float = 17.0

    @property
    def n_lines(self):
        return self.n_lanes + 1

    @property
    def track_width_m(self):
        return self.n_lanes * self.lane_width_m

    def line_y(self, index):
        """``y`` of lane line ``index`` on the straight."""
        return lane_line_y(index, self.lane_width_m)

    def straight_x_range(self):
        """``(x_start, x_end)`` of the straight lane lines (with start area and run-out)."""
        return -self.straight_extension_m, self.straight_length_m + self.runout_m

    def bend_centers(self):
        """Centres ``(x, y)`` of the two bends: fourth bend (x = 0) and first bend (x = straight)."""
        r = self.inner_radius_m
        return np.array([[0.0, r], [self.straight_length_m, r]])

    def bend_line_points(self, index, n=180):
        """Points of lane line ``index`` on both bends, shape (2, n, 3).

        Bend 0 (entering the home straight) spans angles 90..270 deg around its
        centre and bend 1 (after the finish) spans -90..90 deg.
        """
        radius = self.inner_radius_m + self.lane_width_m * index
        out = np.zeros((2, n, 3))
        for b, (centre, (a0, a1)) in enumerate(zip(self.bend_centers(),
                                                     [(np.pi / 2, 3 * np.pi / 2),
                                                      (-np.pi / 2, np.pi / 2)])):
            a = np.linspace(a0, a1, n)
            out[b, :, 0] = centre[0] + radius * np.cos(a)
            out[b, :, 1] = centre[1] + radius * np.sin(a)
        return out

    def _oval(self, radius_m, n):
        """Closed ground polygon (2n, 3): both bends at ``radius_m`` joined by the straights."""
        c0, c1 = self.bend_centers()
        a1 = np.linspace(-np.pi / 2, np.pi / 2, n)
        a0 = a1 + np.pi
        pts = np.concatenate([c1 + radius_m * np.stack([np.cos(a1), np.sin(a1)], -1),
                              c0 + radius_m * np.stack([np.cos(a0), np.sin(a0)], -1)])
        return np.concatenate([pts, np.zeros((len(pts), 1))], axis=1)

    def infield_outline(self, n=90):
        """Closed polygon (N, 3) of the infield edge (inner edge of lane 1)."""
        return self._oval(self.inner_radius_m, n)

    def outer_outline(self, margin_m=0.0, n=90):
        """Closed polygon (N, 3) of the outer edge of the outermost lane plus ``margin_m``
        (the oval only; the straight's start area and run-out are :meth:`straight_surface`)."""
        return self._oval(self.inner_radius_m + self.track_width_m + margin_m, n)

    def straight_surface(self, margin_m=0.0):
        """Rectangle (4, 3) of the home straight's lanes including start area and run-out."""
        x0, x1 = self.straight_x_range()
        y0 = -self.track_width_m - margin_m
        return np.array([[x0, y0, 0], [x1, y0, 0], [x1, 0, 0], [x0, 0, 0]], dtype=float)


#: The standard track used everywhere unless a clip says otherwise.
STANDARD_TRACK = TrackGeometry()
