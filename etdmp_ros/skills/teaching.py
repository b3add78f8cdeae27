"""
Teaching by drawing: a drawing from the teaching page becomes a demonstration (no ROS here).

The node :mod:`etdmp_ros.nodes.teach` serves the page (``etdmp_ros/teach_page/``) and talks to
dmp_server; what it does with the page's data is here, testable without ROS or a browser
(docs/teach.md).

**The canvas** (:class:`Canvas`) is a view of the task plane as the camera sees it, robot base at
the top: ``width_px`` x ``height_px`` logical pixels (4:3, as the camera image) spanning
``width_m`` metres of the plane, centred on its origin; right on the canvas is the plane's
y axis, down its x axis (with the default plane and camera, the camera image's right and down).
A drawing lies on the table as it looked on the canvas, before ET-DMP turns and scales it to a
request's start and goal, and it is never mirrored.

**A drawing** (:func:`parse_drawing`): ``{"name": "Z", "strokes": [[[x, y, t], ...], ...]}``,
x and y in canvas pixels, t the pointer events' ``timeStamp`` in milliseconds: the speed is part
of the demonstration. Strokes (one per pen-down) are joined in order into one movement: the
pen moves from the end of one to the start of the next in a straight line at the drawing's mean
speed, so a pause with the pen up is left out (the connection never takes longer than the pause
did). Points of a stroke that share a time stamp (coalesced events) keep the last one.
Everything else is refused with a :class:`TeachInputError` that says what is wrong: not an
object, a bad skill name (:func:`etdmp_ros.skills.library.check_skill_name`: no ``../x``),
nothing drawn, more than ``MAX_STROKES`` strokes or ``MAX_DRAWN_POINTS`` points (checked
before anything is converted), a point that is not three finite numbers (NaN arrives as JSON
``null``), a point far outside the canvas, times going backwards.

**The same checks as dmp_server.** :func:`taught_path` turns the drawing into the base_link
positions and times the node publishes on ``/etdmp/demonstrations``, resampled evenly in time
(:func:`resampled`: pointer events come unevenly); :func:`learn_drawing`
does with them what dmp_server does with that Path (``recorded_path_demo``, then
``SkillLibrary.add``, which learns it), with dmp_server's own plane, scale, formulation and
basis count. A drawing that fails here is never sent; one that passes is learned by dmp_server
unless something only it knows refuses it (a built-in skill of that name; its reason is shown).

**What the skill does** (:func:`generalizations`): the paper's Fig. 5 for the taught skill, the
ET-DMP and the plain DMP generalizations from a start in each quadrant of the goal (the
demonstration's start direction turned by 0, 90, 180 and 270 degrees), in canvas pixels.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
import json
import math
import re
import threading
from typing import Any

from etdmp_ros import limits
from etdmp_ros.dmp import Demonstration, GeneralizationError, METHODS, nrmse, Skill
from etdmp_ros.geometry.arrays import Array
from etdmp_ros.geometry.camera import CameraIntrinsics, CameraPose
from etdmp_ros.geometry.task_plane import quadrant, TaskPlane
from etdmp_ros.skills.library import check_skill_name, recorded_path_demo, SkillLibrary
import numpy as np
from numpy.typing import ArrayLike

#: Logical size of the canvas in pixels (the camera image's 4:3).
CANVAS_PIXELS = (640, 480)
#: A point may lie this many canvas sizes outside the canvas (the pointer is captured while the
#: pen is down and may leave the canvas); farther is no drawing.
CANVAS_MARGIN = 1.0
#: Largest absolute time stamp accepted (ms): a page's timeStamp counts from its loading.
MAX_TIME_STAMP_MS = 1e12
#: Points per generalization sent to the page (decimated evenly in time).
GENERALIZATION_POINTS = 200
#: Source of a skill learned locally (the check before sending).
SOURCE = 'teaching page'
#: Time between the samples of a taught drawing (s): dmp_server's output_period (see
#: :func:`resampled`).
SAMPLE_PERIOD = 0.01


class TeachInputError(ValueError):
    """What the page sent cannot be taught; the message says why (shown on the page)."""


class MalformedRequest(TeachInputError):
    """The request itself is malformed (HTTP 400): not JSON, nested too deep, a bad Host."""


#: Host names a page served on a loopback address may be asked for (else: DNS rebinding).
LOCAL_NAMES = ('localhost', '127.0.0.1', '::1')
# Host header: an IPv6 literal in brackets or a name / IPv4 address, then an optional port.
_HOST = re.compile(r'(?:\[(?P<ip6>[0-9A-Fa-f:.]+)\]|(?P<name>[A-Za-z0-9._~%!$&\'()*+,;=-]+))'
                   r'(?::(?P<port>[0-9]{0,5}))?')


def request_host(header: str) -> str:
    """
    Return the host name of an HTTP ``Host`` header, lower case (an IPv6 address unbracketed).

    RFC 9110 / 3986: ``host[:port]``, an IPv6 address in brackets (``[::1]:8080``). Raises
    :class:`MalformedRequest` for anything else: ``::1`` without brackets, ``localhost:8080:x``,
    a port that is not a number up to 65535, an unclosed bracket.
    """
    match = _HOST.fullmatch(header)
    port = match and match['port']
    if match is None or (port and int(port) > 65535):
        raise MalformedRequest(f'the Host header {_shown(header)} is not host[:port] (an IPv6 '
                               'address is written in brackets: [::1]:8080)')
    return (match['ip6'] or match['name']).lower()


def is_local(header: str | None) -> bool:
    """
    Return whether a request's ``Host`` header (None: none sent) names this machine.

    A browser always sends the name it asked for, so a web site that points its own name at
    127.0.0.1 (DNS rebinding) is refused; a client without a Host header (HTTP/1.0) can only
    be a program on this machine. Raises :class:`MalformedRequest` for a malformed header.
    """
    return header is None or request_host(header) in LOCAL_NAMES


def _no_constant(name: str) -> float:
    raise ValueError(f'{name} is not a number JSON allows')


def decode_json(body: bytes | str) -> Any:
    """
    Return the JSON value of a request body (bytes); :class:`MalformedRequest` saying why not.

    NaN and Infinity are no JSON and are refused. Nesting deeper than Python's JSON reader goes
    (its recursion limit, about 1000; a drawing nests 4 deep) is refused too: the reader raises
    RecursionError, which is no ValueError.
    """
    try:
        return json.loads(body, parse_constant=_no_constant)
    except RecursionError:
        raise MalformedRequest('the request nests lists or objects deeper than a JSON reader '
                               'allows (a drawing nests 4 deep): nothing was done') from None
    except ValueError as err:   # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise MalformedRequest(f'the request is not valid JSON: {_cut(err)}') from None


def _cut(err: Exception, limit: int = 2 * limits.MAX_REASON_CHARS) -> str:
    text = str(err)
    return text if len(text) <= limit else text[:limit - 3] + '...'


@dataclass(frozen=True)
class Drawing:
    """A checked drawing: canvas pixels ``points`` (n, 2) at times ``t`` (n,) rising from 0 s."""

    name: str
    points: Array
    t: Array
    strokes: int

    @property
    def duration(self) -> float:
        """Return the time from the first to the last point (s)."""
        return float(self.t[-1] - self.t[0])


@dataclass(frozen=True)
class Canvas:
    """The canvas as a view of the task plane (see the module docstring)."""

    width_m: float = 0.4
    width_px: int = CANVAS_PIXELS[0]
    height_px: int = CANVAS_PIXELS[1]

    def __post_init__(self) -> None:
        """Check the sizes."""
        if not (math.isfinite(self.width_m) and self.width_m > 0.0):
            raise ValueError(f'canvas width must be > 0 m, got {self.width_m!r}')
        if self.width_px < 1 or self.height_px < 1:
            raise ValueError(f'canvas size must be positive, got {self.width_px}x'
                             f'{self.height_px}')

    @property
    def metres_per_pixel(self) -> float:
        """Return the size of a canvas pixel on the task plane (m)."""
        return self.width_m / self.width_px

    @property
    def centre(self) -> Array:
        """Return the canvas centre in pixels (2,), where the task plane's origin is."""
        return np.array([self.width_px, self.height_px], dtype=float) / 2.0

    def to_base_link(self, points: ArrayLike, plane: TaskPlane) -> Array:
        """Return base_link points (n, 3) on ``plane`` of canvas pixels ``points`` (n, 2)."""
        offset = (np.asarray(points, dtype=float).reshape(-1, 2) - self.centre) * \
            self.metres_per_pixel
        return plane.origin + offset[:, 1:2] * plane.x_axis + offset[:, 0:1] * plane.y_axis

    def from_plane(self, uv: ArrayLike, plane: TaskPlane) -> Array:
        """Return canvas pixels (..., 2) of task-plane coordinates ``uv`` (..., 2, demo units)."""
        values = np.asarray(uv, dtype=float)
        return values[..., ::-1] * (plane.scale / self.metres_per_pixel) + self.centre


def _stroke(value: object, j: int, canvas: Canvas) -> Array:
    """Return stroke ``j`` as a float (m, 3) array of x, y (px) and t (s); TeachInputError."""
    where = f'stroke {j + 1}'
    if not isinstance(value, list) or not all(isinstance(p, list) for p in value):
        raise TeachInputError(f'{where} is not a list of points [x, y, t]')
    if not value:
        raise TeachInputError(f'{where} is empty: nothing drawn in it')
    bad = next((k for k, p in enumerate(value) if len(p) != 3 or not all(
        isinstance(c, (int, float)) and not isinstance(c, bool) for c in p)), None)
    if bad is not None:
        raise TeachInputError(f'{where}, point {bad + 1}: {_shown(value[bad])} is not three '
                              'numbers [x, y, t] (NaN and infinity arrive as null)')
    array = np.array(value, dtype=float)
    nonfinite = np.flatnonzero(~np.all(np.isfinite(array), axis=1))
    if nonfinite.size:
        raise TeachInputError(f'{where}, point {nonfinite[0] + 1}: '
                              f'{_shown(value[nonfinite[0]])} is not finite')
    size = np.array([canvas.width_px, canvas.height_px], dtype=float)
    outside = np.flatnonzero(np.any((array[:, :2] < -CANVAS_MARGIN * size) |
                                    (array[:, :2] > (1.0 + CANVAS_MARGIN) * size), axis=1))
    if outside.size:
        raise TeachInputError(f'{where}, point {outside[0] + 1}: ({array[outside[0], 0]:.6g}, '
                              f'{array[outside[0], 1]:.6g}) px is far outside the '
                              f'{canvas.width_px}x{canvas.height_px} canvas')
    if np.any(np.abs(array[:, 2]) > MAX_TIME_STAMP_MS):
        raise TeachInputError(f'{where}: a time stamp beyond {MAX_TIME_STAMP_MS:g} ms')
    back = np.flatnonzero(np.diff(array[:, 2]) < 0.0)
    if back.size:
        raise TeachInputError(f'{where}: the time goes backwards at point {back[0] + 2} '
                              f'({array[back[0], 2]:.6g} -> {array[back[0] + 1, 2]:.6g} ms)')
    array[:, 2] *= 1e-3
    # Coalesced events may share a stamp: keep the last (the newest position) of each run.
    keep = np.append(np.diff(array[:, 2]) > limits.MIN_DEMO_SAMPLE_INTERVAL, True)
    return array[keep]


def _shown(value: object) -> str:
    text = repr(value).replace('None', 'null')
    return text if len(text) <= 60 else text[:57] + '...'


def _length(stroke: Array) -> float:
    return float(np.sum(np.linalg.norm(np.diff(stroke[:, :2], axis=0), axis=1)))


def _join(strokes: list[Array]) -> tuple[Array, Array]:
    """Join strokes (m_j, 3) into one timeline (see the module docstring); return (n, 3)."""
    drawn_time = sum(s[-1, 2] - s[0, 2] for s in strokes)
    drawn_length = sum(_length(s) for s in strokes)
    speed = drawn_length / drawn_time if drawn_time > 0.0 and drawn_length > 0.0 else None
    steps = np.concatenate([np.diff(s[:, 2]) for s in strokes])
    step = float(np.median(steps)) if steps.size else 1.0 / 60.0
    pieces = [strokes[0][:, :2]]
    times = [strokes[0][:, 2] - strokes[0][0, 2]]
    for j in range(1, len(strokes)):
        before, after = strokes[j - 1], strokes[j]
        pause = after[0, 2] - before[-1, 2]
        if pause < 0.0:
            raise TeachInputError(f'stroke {j + 1} starts before stroke {j} ends (times '
                                  f'{after[0, 2] * 1e3:.6g} < {before[-1, 2] * 1e3:.6g} ms)')
        gap = float(np.linalg.norm(after[0, :2] - before[-1, :2]))
        moving = gap / speed if speed else pause
        connection = max(min(pause, moving), step)
        end = times[-1][-1]
        inner = int(connection // step) - 1
        if gap > 0.0 and inner > 0:
            fractions = np.arange(1, inner + 1) / (inner + 1)
            pieces.append(before[-1, :2] + fractions[:, None] * (after[0, :2] - before[-1, :2]))
            times.append(end + fractions * connection)
        pieces.append(after[:, :2])
        times.append(end + connection + after[:, 2] - after[0, 2])
        if sum(len(p) for p in pieces) > limits.MAX_DRAWN_POINTS:
            break   # reported by the caller
    return np.concatenate(pieces), np.concatenate(times)


def parse_drawing(data: object, canvas: Canvas = Canvas()) -> Drawing:
    """
    Check what the page sent (decoded JSON) and return the :class:`Drawing`.

    Raises :class:`TeachInputError` saying what is wrong (see the module docstring).
    """
    if not isinstance(data, dict):
        raise TeachInputError('the request must be a JSON object {"name": ..., "strokes": ...}')
    try:
        name = check_skill_name(data.get('name'))
    except ValueError as err:
        raise TeachInputError(str(err)) from None
    strokes = data.get('strokes')
    if not isinstance(strokes, list):
        raise TeachInputError('strokes must be a list of strokes, each a list of points '
                              '[x, y, t]')
    if not strokes or all(isinstance(s, list) and not s for s in strokes):
        raise TeachInputError('nothing drawn: draw the movement on the canvas first')
    if len(strokes) > limits.MAX_STROKES:
        raise TeachInputError(f'{len(strokes)} strokes, more than MAX_STROKES = '
                              f'{limits.MAX_STROKES}')
    count = sum(len(s) if isinstance(s, list) else 0 for s in strokes)
    if count > limits.MAX_DRAWN_POINTS:
        raise TeachInputError(f'{count} points, more than MAX_DRAWN_POINTS = '
                              f'{limits.MAX_DRAWN_POINTS}: draw it more slowly or shorter')
    checked = [_stroke(s, j, canvas) for j, s in enumerate(strokes)]
    points, t = _join(checked)
    if len(points) > limits.MAX_DRAWN_POINTS:
        raise TeachInputError(f'joined, the strokes have {len(points)} points, more than '
                              f'MAX_DRAWN_POINTS = {limits.MAX_DRAWN_POINTS}')
    return Drawing(name, points, t, len(checked))


def resampled(drawing: Drawing) -> tuple[Array, Array]:
    """
    Return (points (m, 2), t (m,)) of a drawing at evenly spaced times (about SAMPLE_PERIOD).

    Pointer events come at uneven intervals: at the display's frame rate, in bursts of
    coalesced events, and not at all while the pen stands still. The DMP's forcing term is
    fitted by least squares to the samples, so a stretch without samples leaves its basis
    functions unconstrained: a Z drawn with gaps of 0.35 s between events (a loaded machine),
    77 samples for 100 basis functions, was reproduced with an excursion of 900 units. The
    drawing is interpolated linearly in time, which keeps its speed; at most MAX_DRAWN_POINTS
    samples (a longer drawing is sampled less often).
    """
    duration = drawing.duration
    n = min(limits.MAX_DRAWN_POINTS, max(2, round(duration / SAMPLE_PERIOD) + 1))
    t = np.linspace(0.0, duration, n)
    points = np.stack([np.interp(t + drawing.t[0], drawing.t, drawing.points[:, i])
                       for i in range(2)], axis=1)
    return points, t


def taught_path(drawing: Drawing, canvas: Canvas, plane: TaskPlane
                ) -> tuple[Array, Array]:
    """
    Return (positions (n, 3) in base_link on ``plane``, times (n,) s) of a drawing: the Path sent.

    Evenly spaced in time (:func:`resampled`).
    """
    points, t = resampled(drawing)
    return canvas.to_base_link(points, plane), t


def learn_drawing(drawing: Drawing, canvas: Canvas, plane: TaskPlane,
                  formulation: str = 'ijspeert', n_basis: int = 100
                  ) -> tuple[Demonstration, Skill]:
    """
    Learn a drawing as dmp_server learns the Path of it; return (Demonstration, Skill).

    ``plane`` (with dmp_server's scale), ``formulation`` and ``n_basis`` are dmp_server's. The
    drawing as drawn must be a demonstration (enough samples, ...) before it is resampled.
    Raises TeachInputError with the reason (the demonstration's or the learning's) when it
    refuses.
    """
    library = SkillLibrary(formulation, n_basis)
    try:
        with np.errstate(over='raise', invalid='raise', divide='raise'):
            recorded_path_demo(drawing.name, canvas.to_base_link(drawing.points, plane),
                               drawing.t, plane, '2d')
            positions, t = taught_path(drawing, canvas, plane)
            demo = recorded_path_demo(drawing.name, positions, t, plane, '2d')
            entry = library.add(drawing.name, demo, SOURCE)
    except (ValueError, ArithmeticError) as err:
        raise TeachInputError(str(err)) from None
    return entry.demo, library.skill(drawing.name)


def _rotation(angle: float) -> Array:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _decimated(x: Array, n: int = GENERALIZATION_POINTS) -> Array:
    index = np.unique(np.linspace(0, len(x) - 1, min(n, len(x))).round().astype(int))
    return x[index]


def uniform(t: ArrayLike, x: ArrayLike, n: int | None = None) -> Array:
    """
    Return samples (n, d) of a movement ``x`` (m, d) at times ``t`` (m,), evenly spaced in time.

    What a generalization is compared with: the similarity measure (nRMSE) pairs samples by
    their index, and pointer events come at uneven intervals, a rollout at even ones. ``n``
    defaults to ``m``.
    """
    given = np.asarray(t, dtype=float)
    values = np.asarray(x, dtype=float)
    times = np.linspace(given[0], given[-1], len(given) if n is None else int(n))
    return np.stack([np.interp(times, given, values[:, i]) for i in range(values.shape[1])],
                    axis=1)


def generalizations(skill: Skill, canvas: Canvas, plane: TaskPlane) -> dict[str, Any]:
    """
    Return the paper's Fig. 5 for ``skill`` (a 2D skill in demo units), JSON-ready, in pixels.

    ``{"demo": [[x, y], ...], "goal": [x, y], "panels": [...]}``: one panel per quadrant I-IV
    of the start relative to the goal, each ``{"quadrant", "own" (the demonstration's
    quadrant), "start", "etdmp": {"path" | "error", "nrmse"}, "dmp": {...}}``, the paths in
    canvas pixels (see :class:`Canvas`).
    """
    goal = np.asarray(skill.goal, dtype=float)
    relative = np.asarray(skill.start, dtype=float) - goal
    own = quadrant(relative)
    starts = np.stack([goal + _rotation(k * math.pi / 2.0) @ relative for k in range(4)])
    demo = uniform(skill.demo_t, skill.demo)
    runs: dict[str, Any] = {}
    for method in METHODS:
        try:
            with np.errstate(over='raise', invalid='raise', divide='raise'):
                runs[method] = skill.generalize(starts, goal, method=method).x
        except (GeneralizationError, ArithmeticError, ValueError) as err:
            runs[method] = str(err)
    panels: list[dict[str, Any]] = []
    for k, start in enumerate(starts):
        panel: dict[str, Any] = {'quadrant': quadrant(start - goal),
                                 'start': canvas.from_plane(start, plane).tolist()}
        panel['own'] = k == 0   # the demonstration's own start
        for method, x in runs.items():
            if isinstance(x, str):
                panel[method] = {'error': x}
                continue
            path = x[k]
            panel[method] = {'path': np.round(canvas.from_plane(_decimated(path), plane), 2)
                             .tolist(), 'nrmse': round(nrmse(path, demo), 4)}
        panels.append(panel)
    panels.sort(key=lambda p: ('I', 'II', 'III', 'IV').index(p['quadrant']))
    return {'demo': np.round(canvas.from_plane(_decimated(skill.demo, 400), plane), 2).tolist(),
            'goal': canvas.from_plane(goal, plane).tolist(), 'quadrant': own,
            'panels': panels}


def project(points: ArrayLike, intrinsics: CameraIntrinsics, camera: CameraPose
            ) -> list[list[float]]:
    """
    Return the pixels (m, 2) of base_link ``points`` (n, 3) in the camera image, as a list.

    ``camera``: the optical frame's :class:`etdmp_ros.geometry.camera.CameraPose`; points
    behind the camera (or within 1 cm of its plane) are left out, and so are points that are no
    place of the workcell (NaN, inf or beyond MAX_REQUEST_COORDINATE: a received plan at 1e308 m
    overflowed into infinite pixels, which JSON cannot carry to the page).
    """
    given = np.asarray(points, dtype=float).reshape(-1, 3)
    given = given[np.all(np.abs(given) <= limits.MAX_REQUEST_COORDINATE, axis=1)]
    optical = (given - np.asarray(camera.position)) @ camera.rotation
    optical = optical[optical[:, 2] > 0.01]
    if not len(optical):
        return []
    return np.round(intrinsics.project(optical), 1).tolist()


class Trace:
    """
    The pen's path as the page draws it; safe to use from several threads.

    Points at least ``spacing`` metres apart, at most ``max_points`` (the oldest dropped).
    """

    def __init__(self, spacing: float = 0.0005, max_points: int = 5000) -> None:
        """Create an empty trace."""
        self.spacing, self.max_points = float(spacing), int(max_points)
        self._points: list[tuple[float, ...]] = []
        self._lock = threading.Lock()

    def add(self, point: Iterable[float]) -> None:
        """Add a point (3,) if it is ``spacing`` from the last one kept."""
        kept = tuple(float(c) for c in point)
        with self._lock:
            if self._points and math.dist(self._points[-1], kept) < self.spacing:
                return
            self._points.append(kept)
            if len(self._points) > self.max_points:
                del self._points[:len(self._points) - self.max_points]

    def clear(self) -> None:
        """Forget every point."""
        with self._lock:
            self._points = []

    def points(self) -> Array:
        """Return the points kept, (n, 3)."""
        with self._lock:
            return np.array(self._points, dtype=float).reshape(-1, 3)
