"""Recorded motion replayed as a motion source: a deck's or a vessel's log, of any length.

A recording is a table ``t, x, y, z, roll, pitch, yaw``: time in seconds (strictly
increasing, from any epoch: a log stamped from 10 s or from a Unix time is fine),
translations in metres, angles in DEGREES (Euler ZYX, :mod:`estimation.frames`).  Two file
formats hold it:

* **CSV** with exactly that header (``write_motion_csv``), parsed by numpy's C reader
  (``np.loadtxt``); a malformed file is scanned again row by row, only to name the line;
* **.npy**, the same seven columns as an (N, 7) float array (``write_motion_npy``), read
  as it is stored, without parsing: a long log converted once loads at once.

A loaded recording is kept per process (keyed by the file's path, size and modification
time), so the episodes after the first do not read it again, and its PCHIP interpolant is
built lazily in chunks of samples (:class:`ChunkedPchip`): an episode of a 2-hour log at
100 Hz touches one or two chunks, not 720 000 samples.

What the samples are (``frame``):

* ``deck``: the deck's pose relative to its home, replayed as it is (the bench's top plate,
  or a helideck's motion measured at the helideck);
* ``vessel``: the vessel's (surge, sway, heave, roll, pitch, yaw) at its centre of motion,
  as a ship's motion monitoring records it; the helideck at ``helideck_position_m`` (x
  forward, y port, z up from that centre) moves with it as a rigid body, exactly as the
  simulated vessel carries its deck (:func:`landing_env.waves.ship.helideck_poses`).

Where an episode starts in the recording (``start``): at the file's own time stamps
(``file_time``: episode time t is file time t, so a log stamped from 10 s holds its first
pose for 10 s), at the first sample (``first_sample``), or at an instant drawn from the
episode's seeded generator (``random``): uniformly over the samples, keeping
``random_margin_s`` of recording after it unless the replay loops.  Seeded episodes then see
different, reproducible stretches of one log.
"""

from __future__ import annotations

import csv
import math
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.interpolate import PchipInterpolator

from estimation.limits import Limit, limited, require_limits
from landing_env.errors import ConfigError, require_choice, require_range
from landing_env.waves.ship import helideck_poses

CSV_HEADER: tuple[str, ...] = ("t", "x", "y", "z", "roll", "pitch", "yaw")
#: ``motion.csv.end``: after the last sample, hold the last pose or loop to the first
RECORDING_ENDS: tuple[str, ...] = ("hold", "loop")
#: ``motion.csv.start``: where episode time 0 falls in the recording
RECORDING_STARTS: tuple[str, ...] = ("file_time", "first_sample", "random")
#: ``motion.csv.frame``: what the samples describe
RECORDING_FRAMES: tuple[str, ...] = ("deck", "vessel")
#: samples per lazily built PCHIP piece (see ChunkedPchip)
CHUNK_SAMPLES = 4096


class CsvMotionError(ValueError):
    """A motion recording is malformed; the message names the file and the row."""


@dataclass(frozen=True)
class CsvMotionConfig:
    """Replay of a recorded motion file (``motion.csv``; see the module docstring)."""

    #: path of the recording, ``.csv`` (header t,x,y,z,roll,pitch,yaw; s, m, degrees) or
    #: ``.npy`` (the same seven columns as an (N, 7) array); required when kind is "csv"
    path: str = ""
    #: after the last sample: "hold" the last pose, or "loop" back to the first sample
    end: Literal["hold", "loop"] = "hold"
    #: where episode time 0 falls: "file_time" (the file's own stamps), "first_sample", or
    #: "random" (drawn from the episode's seed, uniform over the recording)
    start: Literal["file_time", "first_sample", "random"] = "file_time"
    #: start "random" with end "hold": seconds of recording kept after the drawn start (an
    #: episode of up to this length never reaches the held end); s, >= 0
    random_margin_s: float = limited(60.0, Limit(0.0, 1e6))
    #: "deck": the samples are the deck's pose from its home; "vessel": the vessel's motion
    #: at its centre of motion, carried to the helideck (needs deck_mount: ship)
    frame: Literal["deck", "vessel"] = "deck"
    #: frame "vessel": helideck centre from the vessel's centre of motion (x forward, y port,
    #: z up), metres
    helideck_position_m: tuple[float, float, float] = (-10.0, 0.0, 3.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", str(self.path))
        require_choice("end", self.end, RECORDING_ENDS)
        require_choice("start", self.start, RECORDING_STARTS)
        require_choice("frame", self.frame, RECORDING_FRAMES)
        require_limits(self)
        position = tuple(float(v) for v in self.helideck_position_m)
        if len(position) != 3:
            raise ConfigError("helideck_position_m", f"needs 3 values, got {len(position)}")
        for axis, value in zip("xyz", position, strict=True):
            require_range(f"helideck_position_m[{axis}]", value, -200.0, 200.0)
        object.__setattr__(self, "helideck_position_m", position)


# ------------------------------------------------------------------------------- reading
def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """Each row but the blank ones, with the file's line it ends on (blank lines counted)."""
    with path.open(newline="") as handle:
        reader = csv.reader(handle)
        return [(reader.line_num, row) for row in reader if row and any(c.strip() for c in row)]


def _scan_csv(path: Path) -> np.ndarray:
    """Row-by-row parse (N, 7) naming the first bad line: the slow path, for errors."""
    rows = _csv_rows(path)
    if not rows:
        raise CsvMotionError(f"{path}: empty file; expected header {','.join(CSV_HEADER)}")
    _check_header(path, rows[0][1])
    values = np.empty((len(rows) - 1, 7))
    for i, (line, row) in enumerate(rows[1:]):
        if len(row) != 7:
            raise CsvMotionError(f"{path}, line {line}: expected 7 columns, got {len(row)}")
        try:
            values[i] = [float(c) for c in row]
        except ValueError as exc:
            raise CsvMotionError(f"{path}, line {line}: not a number ({exc})") from exc
    return values


def _check_header(path: Path, cells: list[str]) -> None:
    header = tuple(c.strip().lower() for c in cells)
    if header != CSV_HEADER:
        raise CsvMotionError(
            f"{path}: header is {','.join(header)!r}; expected {','.join(CSV_HEADER)!r} "
            "(seconds, metres, degrees)"
        )


def _read_csv(path: Path) -> np.ndarray:
    with path.open(newline="") as handle:
        first = handle.readline()
    if not first.strip():
        return _scan_csv(path)  # names the empty file (or a blank first line)
    _check_header(path, first.strip().split(","))
    try:
        values = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, comments=None)
    except ValueError:
        return _scan_csv(path)
    if values.size == 0:
        values = np.empty((0, 7))
    if values.shape[1] != 7:
        return _scan_csv(path)
    return values


def _read_npy(path: Path) -> np.ndarray:
    try:
        values = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise CsvMotionError(f"{path}: not a numpy array file ({exc})") from exc
    if values.ndim != 2 or values.shape[1] != 7 or not np.issubdtype(values.dtype, np.number):
        raise CsvMotionError(
            f"{path}: holds a {values.dtype} array of shape {values.shape}; expected (N, 7) "
            f"numbers, columns {','.join(CSV_HEADER)} (seconds, metres, degrees)"
        )
    return np.asarray(values, dtype=float)


def read_recording(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Times (N,) in s and poses (N, 6) in m and RADIANS from a ``.csv`` or ``.npy`` file."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"motion recording {str(path)!r} does not exist")
    values = _read_npy(path) if path.suffix.lower() == ".npy" else _read_csv(path)
    if not np.all(np.isfinite(values)):
        row = int(np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0])
        raise CsvMotionError(f"{path}: contains non-finite values (sample {row + 1})")
    if len(values) < 2:
        raise CsvMotionError(f"{path}: needs at least two samples")
    bad = np.flatnonzero(np.diff(values[:, 0]) <= 0.0)
    if len(bad):
        k = int(bad[0]) + 1  # the first sample whose time does not increase
        # a CSV's own line (after its header, blank lines counted); an array's sample
        where = (
            f"sample {k + 1}"
            if path.suffix.lower() == ".npy"
            else f"line {_csv_rows(path)[k + 1][0]}"
        )
        raise CsvMotionError(
            f"{path}, {where}: time {values[k, 0]} does not increase (previous {values[k - 1, 0]})"
        )
    # in place: the table is this function's own (no copies of a long recording)
    np.deg2rad(values[:, 4:], out=values[:, 4:])
    return values[:, 0], values[:, 1:]


def write_motion_csv(path: str | Path, times: np.ndarray, poses: np.ndarray) -> None:
    """Write poses (N, 6; metres and radians) as a motion CSV (angles converted to degrees)."""
    poses = np.asarray(poses, dtype=float).copy()
    poses[:, 3:] = np.rad2deg(poses[:, 3:])
    with Path(path).open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_HEADER)
        for t, row in zip(np.asarray(times, dtype=float), poses, strict=True):
            writer.writerow([repr(float(t)), *(repr(float(v)) for v in row)])


def write_motion_npy(path: str | Path, times: np.ndarray, poses: np.ndarray) -> None:
    """Write poses (N, 6; metres and radians) as an (N, 7) ``.npy`` recording (degrees)."""
    table = np.column_stack([np.asarray(times, dtype=float), np.asarray(poses, dtype=float)])
    table[:, 4:] = np.rad2deg(table[:, 4:])
    np.save(Path(path), table)


# ------------------------------------------------------------------------------- interpolation
class ChunkedPchip:
    """PCHIP through (times, values) built piece by piece, on first use, with a small cache.

    A PCHIP slope at a sample depends only on its two neighbouring intervals, so a piece
    built over ``chunk`` intervals plus two samples of margin on each side equals the
    interpolant of the whole record on those intervals (to rounding).  Outside the samples
    it returns NaN, as ``PchipInterpolator(extrapolate=False)``.
    """

    def __init__(self, times: np.ndarray, values: np.ndarray, chunk: int = CHUNK_SAMPLES) -> None:
        self.times = np.asarray(times, dtype=float)
        self.values = np.asarray(values, dtype=float)
        self.chunk = max(1, int(chunk))
        self._pieces: OrderedDict[int, tuple[PchipInterpolator, object]] = OrderedDict()

    def _piece(self, index: int) -> tuple[PchipInterpolator, object]:
        piece = self._pieces.get(index)
        if piece is None:
            n = len(self.times)
            lo = max(0, index * self.chunk - 2)
            hi = min(n, (index + 1) * self.chunk + 3)
            interp = PchipInterpolator(
                self.times[lo:hi], self.values[lo:hi], axis=0, extrapolate=False
            )
            piece = (interp, interp.derivative())
            self._pieces[index] = piece
            if len(self._pieces) > 8:
                self._pieces.popitem(last=False)
        else:
            self._pieces.move_to_end(index)
        return piece

    def __call__(self, t: np.ndarray, derivative: bool = False) -> np.ndarray:
        t = np.asarray(t, dtype=float).reshape(-1)
        out = np.full((len(t), self.values.shape[1]), np.nan)
        inside = (t >= self.times[0]) & (t <= self.times[-1])
        interval = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        chunks = interval // self.chunk
        for index in np.unique(chunks[inside]):
            mask = inside & (chunks == index)
            interp, rate = self._piece(int(index))
            out[mask] = (rate if derivative else interp)(t[mask])
        return out


@dataclass(frozen=True)
class Recording:
    """Loaded samples (times s, poses m/rad relative to home) and their lazy interpolant."""

    times: np.ndarray
    samples: np.ndarray
    interpolant: ChunkedPchip

    @classmethod
    def from_samples(cls, times: np.ndarray, poses: np.ndarray) -> Recording:
        times = np.asarray(times, dtype=float)
        poses = np.asarray(poses, dtype=float)
        if times.ndim != 1 or len(times) < 2 or poses.shape != (len(times), 6):
            raise CsvMotionError("need at least two samples of (t, x, y, z, roll, pitch, yaw)")
        bad = np.flatnonzero(np.diff(times) <= 0.0)
        if len(bad):
            raise CsvMotionError(f"time must increase strictly; it does not at sample {bad[0] + 1}")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(poses))):
            raise CsvMotionError("samples must be finite")
        return cls(times, poses, ChunkedPchip(times, poses))


_RECORDINGS: OrderedDict[tuple, Recording] = OrderedDict()


def load_recording(
    path: str | Path,
    frame: str = "deck",
    helideck_position_m: tuple[float, float, float] = (-10.0, 0.0, 3.0),
) -> Recording:
    """The recording in ``path`` as deck poses (see the module), read once per process."""
    require_choice("frame", frame, RECORDING_FRAMES)
    resolved = Path(path).expanduser().resolve()
    if not resolved.is_file():
        raise FileNotFoundError(f"motion recording {str(path)!r} does not exist")
    stat = resolved.stat()
    lever = tuple(float(v) for v in helideck_position_m)
    key = (str(resolved), stat.st_size, stat.st_mtime_ns, frame, lever if frame == "vessel" else ())
    recording = _RECORDINGS.get(key)
    if recording is None:
        times, poses = read_recording(resolved)
        if frame == "vessel":
            poses = helideck_poses(poses, np.asarray(lever))
        recording = Recording.from_samples(times, poses)
        _RECORDINGS[key] = recording
        if len(_RECORDINGS) > 4:
            _RECORDINGS.popitem(last=False)
    else:
        _RECORDINGS.move_to_end(key)
    return recording


# ------------------------------------------------------------------------------- source
class CsvMotion:
    """PCHIP replay of a recording; episode time t plays file time ``t + offset_s``.

    Before the first sample the first pose is held; after the last one the last pose is
    held (``end`` "hold") or the file starts again from its first sample (``end`` "loop";
    file time then wraps as ``start + (tau - start) mod duration``).  ``pose``, ``poses``
    and ``velocity`` share that one mapping of time.
    """

    def __init__(
        self,
        times: np.ndarray | Recording,
        poses: np.ndarray | None = None,
        end: Literal["hold", "loop"] = "hold",
        offset_s: float = 0.0,
    ) -> None:
        if isinstance(times, Recording):
            recording = times
        else:
            recording = Recording.from_samples(np.asarray(times), np.asarray(poses))
        require_choice("end", end, RECORDING_ENDS)
        if not math.isfinite(offset_s):
            raise ValueError(f"offset_s must be finite, got {offset_s!r}")
        self.recording = recording
        self.times = recording.times
        self.samples = recording.samples
        self.end = end
        self.offset_s = float(offset_s)
        self._start, self._stop = float(self.times[0]), float(self.times[-1])

    @classmethod
    def from_file(
        cls,
        path: str | Path,
        end: Literal["hold", "loop"] = "hold",
        offset_s: float = 0.0,
        frame: str = "deck",
        helideck_position_m: tuple[float, float, float] = (-10.0, 0.0, 3.0),
    ) -> CsvMotion:
        """Replay ``path`` (``.csv`` or ``.npy``; see the module docstring)."""
        return cls(load_recording(path, frame, helideck_position_m), end=end, offset_s=offset_s)

    @property
    def duration(self) -> float:
        """Time span of the samples (s)."""
        return self._stop - self._start

    def file_times(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """File times (N,) played at episode ``times`` and whether the pose is held there."""
        tau = np.asarray(times, dtype=float).reshape(-1) + self.offset_s
        held = tau <= self._start
        local = np.maximum(tau, self._start)
        after = tau >= self._stop
        if self.end == "hold":
            local[after] = self._stop
            held |= after
        else:
            local[after] = self._start + np.fmod(tau[after] - self._start, self.duration)
        return np.clip(local, self._start, self._stop), held

    def poses(self, times: np.ndarray) -> np.ndarray:
        local, _ = self.file_times(times)
        return self.recording.interpolant(local)

    def pose(self, t: float) -> np.ndarray:
        return self.poses(np.array([t]))[0]

    def velocities(self, times: np.ndarray) -> np.ndarray:
        """Time derivative of :meth:`poses` (zero where a pose is held), (N, 6)."""
        local, held = self.file_times(times)
        rates = self.recording.interpolant(local, derivative=True)
        rates[held] = 0.0
        return rates

    def velocity(self, t: float) -> np.ndarray:
        return self.velocities(np.array([t]))[0]


def csv_motion_from_config(config: CsvMotionConfig, rng: np.random.Generator) -> CsvMotion:
    """The replay ``config`` describes; a "random" start is drawn from ``rng`` (one draw)."""
    recording = load_recording(config.path, config.frame, config.helideck_position_m)
    first = float(recording.times[0])
    if config.start == "file_time":
        offset = 0.0
    elif config.start == "first_sample":
        offset = first
    else:
        span = float(recording.times[-1]) - first
        if config.end == "hold":
            span = max(0.0, span - config.random_margin_s)
        offset = first + float(rng.uniform(0.0, 1.0)) * span
    return CsvMotion(recording, end=config.end, offset_s=offset)
