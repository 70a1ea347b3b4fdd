"""Presses and sites of a stage log (host): where the stage pushed, and where it was.

A stage log's `indentation` column is the stage's travel towards the skin: at rest
between presses it sits at its home, during a press it ramps up, holds and ramps back.
A **press** is a maximal run of samples whose travel is above the rest level by more
than `threshold` of the log's travel range (default 5 %, :data:`PRESS_THRESHOLD`),
widened on both sides to the samples where the travel leaves and regains its rest
level (the contact can start anywhere on the ramp: its onset is what the fit finds).
The rest level is the travel's 5th percentile; runs shorter than `min_samples` are
stage noise, not presses.

A gap in the log can swallow a press's retract, the move and the next approach: a run
above the threshold in which the stage stands at a new site after a gap is cut there,
and the piece after the cut is flagged *unseen* (its loading happened in the gap).

A **site** is a stage position (`stage_x`, `stage_y`, or the columns a mapping names)
shared by presses: positions within `site_tolerance` (default 1 um) are one site. A
log without position columns has one site per press. The position must not change
during a press; a log where it does is refused with the row.
"""

import dataclasses

import numpy as np

from ..._errors import HydrotactError

PRESS_THRESHOLD = 0.05  # of the travel's range above its rest level
SITE_TOLERANCE = 1e-6  # m: stage positions closer than this are one site
GAP_FACTOR = 5.0  # a step this many times the typical one is a gap in the log
POSITION_COLUMNS = ("stage_x", "stage_y")


@dataclasses.dataclass(frozen=True)
class Presses:
    """The presses of one log: `starts`, `ends` (P,) sample indices (end exclusive);
    `sites` (P,) the site of each press; `positions` (S, k) each site's stage
    position (k = 0 without position columns); `unseen` (P,) whether a press began
    in a gap of the log (its loading history is unknown)."""

    starts: np.ndarray
    ends: np.ndarray
    sites: np.ndarray
    positions: np.ndarray
    unseen: np.ndarray

    @property
    def num_presses(self) -> int:
        return len(self.starts)

    @property
    def num_sites(self) -> int:
        return len(self.positions)

    def select(self, keep) -> "Presses":
        """The presses where `keep` (P,) is True (the sites and positions unchanged)."""
        keep = np.asarray(keep, dtype=bool)
        return dataclasses.replace(self, starts=self.starts[keep], ends=self.ends[keep], sites=self.sites[keep], unseen=self.unseen[keep])

    def press_of_samples(self, num_samples: int) -> np.ndarray:
        """(T,) the press each sample belongs to, -1 between presses."""
        index = np.full(num_samples, -1)
        for k, (start, end) in enumerate(zip(self.starts, self.ends)):
            index[start:end] = k
        return index


def _split_at_hidden_moves(times, positions, starts, ends, tolerance):
    """Runs cut where the stage stands at a new site after a gap in the log (the
    retract, the move and the next approach fell into the gap); the pieces after a
    cut are flagged unseen."""
    steps = np.diff(times)
    typical = float(np.median(steps)) if len(steps) else 0.0
    pieces = []
    for start, end in zip(starts, ends):
        moved = np.any(np.abs(np.diff(positions[start:end], axis=0)) > tolerance, axis=1)
        cuts = [start + 1 + int(r) for r in np.flatnonzero(moved) if steps[start + r] > GAP_FACTOR * typical]
        bounds = [start, *cuts, end]
        pieces += [(bounds[i], bounds[i + 1], i > 0) for i in range(len(bounds) - 1)]
    return pieces


def find_presses(
    travel, *, threshold: float = PRESS_THRESHOLD, min_samples: int = 3, positions=None, times=None, tolerance: float = SITE_TOLERANCE,
    source: str = "log",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts, ends, unseen) of the presses in a travel column (see the module's
    docstring). With `positions` (T, k) and `times` (T,), a run above the threshold
    is cut where the stage stands at a new site after a gap longer than GAP_FACTOR
    sampling steps (the piece after the cut began unseen), and a press is not widened
    onto samples where the stage stands elsewhere than at its deepest sample (it moves
    to the next site while it regains its rest level: a rest of 0.1 s is one or two
    samples)."""
    travel = np.asarray(travel, dtype=np.float64)
    if not 0.0 < threshold < 1.0:
        raise HydrotactError(f"--press-threshold: must be between 0 and 1 (a fraction of the travel's range), got {threshold:g}")
    rest = float(np.percentile(travel, 5.0))
    span = float(np.max(travel)) - rest
    if not span > 0.0:
        raise HydrotactError(f"{source}: the indentation column never moves above its rest level: no presses to fit")
    above = travel > rest + threshold * span
    edges = np.diff(np.concatenate([[0], above.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    positions = np.zeros((len(travel), 0)) if positions is None else np.asarray(positions, dtype=np.float64).reshape(len(travel), -1)
    if times is not None and positions.shape[1]:
        pieces = _split_at_hidden_moves(np.asarray(times, dtype=np.float64), positions, starts, ends, tolerance)
        starts, ends, unseen = (np.array([piece[i] for piece in pieces], dtype=np.int64) for i in range(3))
        unseen = unseen.astype(bool)
    else:
        unseen = np.zeros(len(starts), dtype=bool)
    keep = ends - starts >= min_samples
    starts, ends, unseen = starts[keep], ends[keep], unseen[keep]
    if not len(starts):
        raise HydrotactError(f"{source}: no press lasts {min_samples} samples above {threshold:.0%} of the indentation's range")
    # Widen to where the stage leaves and regains its rest level (a small fraction of
    # the range: the rest level itself is noisy on real stages).
    moving = travel > rest + 0.01 * threshold * span
    for k in range(len(starts)):
        here = positions[starts[k] + int(np.argmax(travel[starts[k] : ends[k]]))]

        def same_site(row, here=here):
            return bool(np.all(np.abs(positions[row] - here) <= tolerance))

        while starts[k] > 0 and moving[starts[k] - 1] and (k == 0 or starts[k] - 1 >= ends[k - 1]) and same_site(starts[k] - 1):
            starts[k] -= 1
        while ends[k] < len(travel) and moving[ends[k]] and (k + 1 == len(starts) or ends[k] < starts[k + 1]) and same_site(ends[k]):
            ends[k] += 1
    return starts, ends, unseen


def group_sites(positions, starts, ends, *, tolerance: float = SITE_TOLERANCE, names=POSITION_COLUMNS, source: str = "log") -> tuple[np.ndarray, np.ndarray]:
    """(site of each press, each site's position) from (T, k) stage positions;
    refuses a position that moves during a press."""
    positions = np.asarray(positions, dtype=np.float64).reshape(len(positions), -1)
    if positions.shape[1] == 0:
        return np.arange(len(starts)), np.zeros((len(starts), 0))
    press_positions = []
    for start, end in zip(starts, ends):
        block = positions[start:end]
        moved = np.flatnonzero(np.any(np.abs(block - block[0]) > tolerance, axis=1))
        if moved.size:
            row, column = start + int(moved[0]), int(np.flatnonzero(np.abs(block[moved[0]] - block[0]) > tolerance)[0])
            raise HydrotactError(f"{source}: column {names[column]!r}, row {row + 1}: the stage moves during a press (from row {start + 1}); a lumped fit needs each press at one site")
        press_positions.append(block[0])
    sites, centres = np.zeros(len(starts), dtype=np.int64), []
    for k, position in enumerate(press_positions):
        match = [s for s, centre in enumerate(centres) if np.all(np.abs(position - centre) <= tolerance)]
        if match:
            sites[k] = match[0]
        else:
            sites[k] = len(centres)
            centres.append(position)
    return sites, np.array(centres)


def find_log_presses(log, indentation: str = "indentation", position_columns=POSITION_COLUMNS, *, threshold: float = PRESS_THRESHOLD, source: str = "log") -> Presses:
    """The presses and sites of a BarometerLog: `indentation` the travel column,
    `position_columns` the stage position columns (those absent are ignored; none: one
    site per press)."""
    if indentation not in log.columns:
        raise HydrotactError(f"{source}: no indentation column {indentation!r} (has {', '.join(log.columns)})")
    names = tuple(name for name in position_columns if name in log.columns)
    positions = np.column_stack([np.asarray(log.columns[name], dtype=np.float64) for name in names]) if names else np.zeros((log.num_samples, 0))
    starts, ends, unseen = find_presses(log.columns[indentation], threshold=threshold, positions=positions, times=log.times, source=source)
    sites, centres = group_sites(positions, starts, ends, names=names, source=source)
    return Presses(starts=starts, ends=ends, sites=sites, positions=centres, unseen=unseen)
