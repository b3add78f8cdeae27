"""
Teaching by drawing without a browser or the system: the page's data, checked and learned.

:mod:`etdmp_ros.skills.teaching` (drawing → base_link path → the demonstration dmp_server
learns, the Fig. 5 generalizations, the camera projection) and the teach node in this process: its
parameters, its page files, its JSON API's answers to bad requests, its host check. The page in
a real browser with the whole system: test_teach_page.py.
"""

import json
import math
import socket
import time
import urllib.error
import urllib.request

from conftest import REPO
from etdmp_ros import limits
from etdmp_ros.dmp import nrmse
from etdmp_ros.geometry.camera import CameraIntrinsics, CameraPose
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.ros import config_files, system
from etdmp_ros.ros.conversions import path_from_cdr, path_from_numpy
from etdmp_ros.skills import teaching
from etdmp_ros.skills.library import recorded_path_demo, SkillLibrary
from geometry_msgs.msg import PointStamped, PoseStamped
import numpy as np
import pytest
import rclpy
from rclpy.serialization import serialize_message
from support.drawings import letter_z, request, stroke

PLANE = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
CANVAS = teaching.Canvas()


def test_the_canvas_is_the_task_plane_as_the_camera_sees_it():
    centre = CANVAS.to_base_link([[320.0, 240.0]], PLANE)[0]
    assert np.allclose(centre, PLANE.origin)
    mpp = 0.4 / 640
    right, down = CANVAS.to_base_link([[420.0, 240.0], [320.0, 340.0]], PLANE)
    assert np.allclose(right - centre, [0.0, 100 * mpp, 0.0])   # right: +y (camera image right)
    assert np.allclose(down - centre, [100 * mpp, 0.0, 0.0])    # down: +x (towards the camera)
    # The camera of the scene sees +y to the right and +x downwards too.
    scene = system.scene_defaults()
    camera = CameraPose(scene['camera.position'], scene['camera.orientation'])
    intrinsics = CameraIntrinsics.from_fovy(640, 480, 42.5)
    pixels = np.array(teaching.project([centre, right, down], intrinsics, camera))
    assert pixels[1, 0] > pixels[0, 0] + 10 and abs(pixels[1, 1] - pixels[0, 1]) < 10
    assert pixels[2, 1] > pixels[0, 1] + 10 and abs(pixels[2, 0] - pixels[0, 0]) < 10
    # Back from the plane's demo units to the canvas.
    points = letter_z()
    uv = PLANE.to_plane(CANVAS.to_base_link(points, PLANE))
    assert np.allclose(CANVAS.from_plane(uv, PLANE), points)


def test_a_drawing_is_its_points_at_the_pointer_events_times():
    drawing = teaching.parse_drawing(request('Zed'), CANVAS)
    assert drawing.name == 'Zed' and drawing.strokes == 1
    assert np.allclose(drawing.points, letter_z())
    assert np.allclose(np.diff(drawing.t), 0.0167) and drawing.t[0] == 0.0   # from the first
    positions, t = teaching.taught_path(drawing, CANVAS, PLANE)   # evenly resampled
    assert np.allclose(np.diff(t), teaching.SAMPLE_PERIOD, rtol=0.01) and t[0] == 0.0
    assert len(t) == round(drawing.duration / teaching.SAMPLE_PERIOD) + 1
    assert math.isclose(t[-1], drawing.duration) and np.allclose(positions[:, 2], 0.0)
    assert np.allclose(positions[[0, -1]], CANVAS.to_base_link(letter_z()[[0, -1]], PLANE))


def test_uneven_pointer_events_are_resampled_before_learning():
    """A loaded machine's pointer events: gaps of up to 0.35 s between them (seen in a run)."""
    points = letter_z()
    gaps = np.random.default_rng(3).choice([0.03, 0.03, 0.03, 0.05, 0.25, 0.35], len(points))
    t = 1000.0 * np.concatenate([[0.0], np.cumsum(gaps[1:])])
    strokes = [[[float(x), float(y), float(ti)] for (x, y), ti in zip(points, t)]]
    drawing = teaching.parse_drawing(request('Z', strokes), CANVAS)
    demo, skill = teaching.learn_drawing(drawing, CANVAS, PLANE)
    assert demo.n_samples == round(drawing.duration / teaching.SAMPLE_PERIOD) + 1
    shown = teaching.generalizations(skill, CANVAS, PLANE)
    assert max(p['etdmp']['nrmse'] for p in shown['panels']) < 0.01
    # The drawing sent (evenly in time) against the reproduction at each sample's time on the
    # skill's clock: resampled linearly between sparse events, this drawing starts moving and
    # is learned speeding up from rest there (docs/design.md#coming-to-rest).
    rollout = skill.generalize(skill.start, skill.goal)
    on_clock = np.stack([np.interp(skill.retiming.times, rollout.t, rollout.x[:, i])
                         for i in range(2)], axis=1)
    drawn = PLANE.to_plane(CANVAS.to_base_link(drawing.points, PLANE))
    drawn = teaching.uniform(drawing.t, drawn, demo.n_samples)
    assert nrmse(on_clock, drawn) < 0.01


def test_points_sharing_a_time_keep_the_last_and_strokes_are_joined_without_the_pause():
    points = letter_z()
    first = stroke(points[:40])
    first.insert(5, [first[5][0] - 3.0, first[5][1], first[5][2]])   # coalesced: same stamp
    second = stroke(points[50:], start_ms=first[-1][2] + 4000.0)     # a 4 s pause, pen up
    drawing = teaching.parse_drawing(request('two', [first, second]), CANVAS)
    assert drawing.strokes == 2
    assert np.all(np.diff(drawing.t) > 0.0)
    assert np.allclose(drawing.points[:40], points[:40])             # the later one kept
    gap = np.linalg.norm(points[50] - points[39])
    speed = sum(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()
                for p in (points[:40], points[50:])) / (0.0167 * (39 + len(points) - 51))
    joined = drawing.duration - 0.0167 * (39 + len(points) - 51)
    assert math.isclose(joined, gap / speed, rel_tol=1e-6), (joined, gap / speed)
    inner = drawing.points[40:-len(points[50:])]
    assert len(inner) >= 1   # the pen's straight way from one stroke to the next
    direction = (points[50] - points[39]) / gap
    offsets = inner - points[39]
    assert np.allclose(offsets - (offsets @ direction)[:, None] * direction, 0.0, atol=1e-9)


#: Bad input from the page and the reason it gets (a fragment of it).
BAD = {
    'not an object': ([1, 2], 'must be a JSON object'),
    'no name': ({'strokes': [stroke(letter_z())]}, 'skill name None is not valid'),
    'a path as name': (request('../x'), "skill name '../x' is not valid"),
    'a name with a slash': (request('a/b'), "skill name 'a/b' is not valid"),
    'strokes missing': ({'name': 'Z'}, 'strokes must be a list'),
    'no stroke': (request('Z', []), 'nothing drawn'),
    'only empty strokes': (request('Z', [[], []]), 'nothing drawn'),
    'an empty stroke': (request('Z', [stroke(letter_z()), []]), 'stroke 2 is empty'),
    'NaN (JSON null)': (request('Z', [[[1.0, 2.0, 3.0], [None, 2.0, 4.0]]]),
                        'stroke 1, point 2: [null, 2.0, 4.0] is not three numbers'),
    'a string': (request('Z', [[[1.0, 'a', 3.0]]]), 'is not three numbers'),
    'a boolean': (request('Z', [[[1.0, True, 3.0]]]), 'is not three numbers'),
    'two numbers': (request('Z', [[[1.0, 2.0]]]), 'is not three numbers'),
    'infinity': (request('Z', [[[1.0, 2.0, 3.0], [math.inf, 2.0, 4.0]]]), 'is not finite'),
    'far outside the canvas': (request('Z', [[[1.0, 2.0, 3.0], [1e6, 2.0, 4.0]]]),
                               'far outside the 640x480 canvas'),
    'time going backwards': (request('Z', [[[1.0, 2.0, 30.0], [2.0, 2.0, 20.0]]]),
                             'the time goes backwards at point 2'),
    'strokes overlapping in time': (
        request('Z', [stroke(letter_z()[:20]), stroke(letter_z()[20:])]),
        'stroke 2 starts before stroke 1 ends'),
    'too many strokes': (request('Z', [[[1.0, 2.0, float(k)]] for k in range(101)]),
                         'more than MAX_STROKES = 100'),
}


@pytest.mark.parametrize('what', BAD)
def test_bad_input_from_the_page_is_refused_with_the_reason(what):
    data, reason = BAD[what]
    with pytest.raises(teaching.TeachInputError) as error:
        teaching.parse_drawing(data, CANVAS)
    assert reason in str(error.value), str(error.value)


def test_a_million_points_are_refused_before_any_is_converted():
    data = request('Z', [[[1.5, 2.5, 3.5]] * 1_000_000])
    started = time.perf_counter()
    with pytest.raises(teaching.TeachInputError, match='1000000 points, more than '
                       f'MAX_DRAWN_POINTS = {limits.MAX_DRAWN_POINTS}'):
        teaching.parse_drawing(data, CANVAS)
    assert time.perf_counter() - started < 0.5


def test_what_dmp_server_refuses_is_refused_before_sending():
    few = teaching.parse_drawing(request('Z', [stroke(letter_z()[:5])]), CANVAS)
    with pytest.raises(teaching.TeachInputError, match='5 samples; a demonstration needs at '
                       'least 10'):
        teaching.learn_drawing(few, CANVAS, PLANE)
    dot = teaching.parse_drawing(request('Z', [stroke([[100.0, 100.0]] * 20)]), CANVAS)
    with pytest.raises(teaching.TeachInputError, match='does not move'):
        teaching.learn_drawing(dot, CANVAS, PLANE)


def test_the_check_learns_exactly_what_dmp_server_learns_from_the_path_sent():
    """The Path the node publishes, read as dmp_server reads it, gives the same skill."""
    drawing = teaching.parse_drawing(request('Z'), CANVAS)
    demo, skill = teaching.learn_drawing(drawing, CANVAS, PLANE)
    positions, t = teaching.taught_path(drawing, CANVAS, PLANE)
    sent = serialize_message(path_from_numpy(positions, t, 1_800_000_000 * 10**9, 'base_link'))
    _, _, stamps, received, _ = path_from_cdr(sent)
    server = SkillLibrary()
    entry = server.add('Z', recorded_path_demo('Z', received, (stamps - stamps[0]) * 1e-9,
                                               PLANE, 'auto', 0.01), 'taught')
    assert np.allclose(entry.demo.positions, demo.positions, atol=1e-9)
    assert np.allclose(entry.demo.t, demo.t, atol=1e-9)
    ours = skill.generalize([0.0, 3.0], [1.0, -2.0]).x
    theirs = server.skill('Z').generalize([0.0, 3.0], [1.0, -2.0]).x
    assert np.allclose(ours, theirs, atol=1e-9)
    # In demo units the Z is the canvas drawing: 200 px = 0.125 m = 6.25 units wide.
    assert np.allclose(np.ptp(demo.positions, axis=0), [220 * 0.4 / 640 / 0.02, 6.25])


def test_the_generalizations_are_the_paper_s_fig5_for_the_drawing():
    drawing = teaching.parse_drawing(request('Z'), CANVAS)
    demo, skill = teaching.learn_drawing(drawing, CANVAS, PLANE)
    shown = teaching.generalizations(skill, CANVAS, PLANE)
    json.dumps(shown)
    assert shown['quadrant'] == 'III'   # the Z starts up-left of its end: -x, -y in the plane
    assert [p['quadrant'] for p in shown['panels']] == ['I', 'II', 'III', 'IV']
    assert [p['own'] for p in shown['panels']] == [False, False, True, False]
    assert np.allclose(shown['demo'][0], letter_z()[0], atol=0.01)
    for panel in shown['panels']:
        assert panel['etdmp']['nrmse'] < 0.01, panel['quadrant']   # the shape, from anywhere
        path = np.array(panel['etdmp']['path'])
        assert len(path) <= teaching.GENERALIZATION_POINTS
        assert np.allclose(path[0], panel['start'], atol=0.01)
        assert np.linalg.norm(path[-1] - shown['goal']) < 2.0   # pixels
    by_quadrant = {p['quadrant']: p for p in shown['panels']}
    assert by_quadrant['III']['dmp']['nrmse'] < 0.01        # the DMP: only its own quadrant
    assert min(by_quadrant[q]['dmp']['nrmse'] for q in ('II', 'IV')) > 0.3


#: Strokes drawn with the pen lifted while it still moves, in canvas pixels: the Z
#: lifted half way along its last part, a circle and a spiral drawn at speed to the end.
_CIRCLE = np.linspace(0.0, 1.8 * math.pi, 90)
_SPIRAL = np.linspace(0.0, 4.0 * math.pi, 150) ** 1.3
LIFTED = {
    'Z lifted': letter_z()[:63],
    'circle': np.c_[320 + 120 * np.cos(_CIRCLE), 240 + 120 * np.sin(_CIRCLE)],
    'spiral': np.c_[320 + (30 + 10 * _SPIRAL) * np.cos(_SPIRAL) / 3,
                    240 + (30 + 10 * _SPIRAL) * np.sin(_SPIRAL) / 3],
}


@pytest.mark.parametrize('name', list(LIFTED))
def test_a_stroke_lifted_while_moving_is_learned_coming_to_rest(name):
    """A drawing that ends (or starts) at speed: every plan still ends at its goal, at rest."""
    drawing = teaching.parse_drawing(request('S', [stroke(LIFTED[name])]), CANVAS)
    demo, skill = teaching.learn_drawing(drawing, CANVAS, PLANE)
    assert skill.retiming.end > 0.0     # learned as slowing to rest along its own path
    goal = skill.goal
    offset = skill.start - goal
    for method in ('etdmp', 'dmp'):
        for k in range(4):              # a start in each quadrant, as the page shows
            c, s = math.cos(k * math.pi / 2), math.sin(k * math.pi / 2)
            start = goal + (1.0 + 0.2 * k) * np.array([[c, -s], [s, c]]) @ offset
            try:
                traj = skill.generalize(start, goal, method=method, margin=1.0)
            except ValueError as err:   # the plain DMP's division by ~0 (a closed stroke)
                assert method == 'dmp' and 'plain DMP cannot' in str(err)
                continue
            dist = np.linalg.norm(traj.x - goal, axis=1)
            n = (len(traj.t) - 1) // 2
            size = dist[:n + 1].max()
            assert dist[n:].max() <= 0.005 * size, (method, k)      # after tau
            assert dist[-1] <= 0.001 * size and np.linalg.norm(traj.v[-1]) * skill.tau <= \
                0.01 * size, (method, k)                            # at 2 tau
    # The path drawn is the path learned: the drawn samples outside the slowed stretches are
    # learned as they are, at their re-timed times; those inside lie on the curve through
    # them (sampled finer: between its samples, within 0.5 mm).
    times, drawn = skill.retiming.times, demo.positions
    index = np.minimum(np.searchsorted(skill.demo_t, times), len(skill.demo_t) - 1)
    kept = np.abs(skill.demo_t[index] - times) <= 1e-12
    assert kept.mean() > 0.8 and np.array_equal(skill.demo[index[kept]], drawn[kept])
    between = np.stack([np.interp(times, skill.demo_t, skill.demo[:, i]) for i in range(2)], 1)
    assert np.max(np.linalg.norm(between - drawn, axis=1)) * PLANE.scale < 5e-4
    # A Z drawn to rest at its end is not re-timed there.
    _, at_rest = teaching.learn_drawing(teaching.parse_drawing(request('Z'), CANVAS), CANVAS,
                                        PLANE)
    assert at_rest.retiming.end == 0.0


def test_a_closed_stroke_shows_why_the_plain_dmp_refuses_it():
    angle = np.linspace(0.0, 2 * math.pi * 0.98, 80)
    ring = np.stack([320 + 80 * np.cos(angle), 240 + 80 * np.sin(angle)], axis=1)
    ring[:, 1] = np.where(np.arange(80) == 79, ring[0, 1], ring[:, 1])   # ends at its start's y
    drawing = teaching.parse_drawing(request('O', [stroke(ring)]), CANVAS)
    _, skill = teaching.learn_drawing(drawing, CANVAS, PLANE)
    shown = teaching.generalizations(skill, CANVAS, PLANE)
    assert all('path' in p['etdmp'] for p in shown['panels'])
    refused = [p['dmp'] for p in shown['panels'] if 'error' in p['dmp']]
    assert all(isinstance(r['error'], str) and r['error'] for r in refused)


def test_points_project_into_the_camera_image_or_are_left_out_behind_it():
    camera = CameraPose.look_at([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], up=(1.0, 0.0, 0.0))
    intrinsics = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5)
    pixels = teaching.project([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0], [0.1, 0.0, 0.0]], intrinsics,
                              camera)
    assert len(pixels) == 2
    assert np.allclose(pixels[0], [319.5, 239.5])
    assert teaching.project(np.zeros((0, 3)), intrinsics, camera) == []
    # A plan or trace point at 1e308 m (or NaN) is no pixel (it was inf: no JSON for the page).
    with np.errstate(over='raise', invalid='raise'):
        pixels = teaching.project([[0.0, 0.0, 0.0], [1e308, 0.0, 0.0], [np.nan, 0.0, 0.0]],
                                  intrinsics, camera)
    assert np.allclose(pixels, [[319.5, 239.5]])


def test_the_trace_keeps_points_a_spacing_apart_and_at_most_its_size():
    trace = teaching.Trace(spacing=0.0009, max_points=10)
    for x in 0.0005 * np.arange(41):
        trace.add([x, 0.0, 0.0])
    points = trace.points()
    assert len(points) == 10 and np.allclose(np.diff(points[:, 0]), 0.001)
    assert math.isclose(points[-1, 0], 0.02)
    trace.clear()
    assert trace.points().shape == (0, 3)


# --------------------------------------------------------------------------------- the node

@pytest.mark.parametrize('kind', (PointStamped, PoseStamped))
def test_the_trace_reader_reads_a_point_at_every_frame_id_length(kind):
    from etdmp_ros.nodes.teach import point_from_cdr
    for frame in ('', 'a', 'ab', 'abc', 'base', 'base_link', 'base_link_x', 'tool_tip_frame'):
        msg = kind()
        msg.header.frame_id = frame
        msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 34
        point = msg.point if kind is PointStamped else msg.pose.position
        point.x, point.y, point.z = 0.1, -0.2, 0.3
        assert point_from_cdr(serialize_message(msg)) == (0.1, -0.2, 0.3), frame
    with pytest.raises(ValueError):
        point_from_cdr(serialize_message(kind())[:20])


def test_the_parameter_file_gives_back_every_default():
    spec = system.node('teach')
    assert spec not in system.NODES   # not started by make demo, bringup, the default launch
    assert system.parameter_files('teach')[1].name == 'teach.yaml'
    from_files = config_files.read_node_parameters('teach')
    for p in spec.all_parameters:
        assert from_files[p.name] == p.default and type(from_files[p.name]) is type(p.default)
    assert (REPO / 'docs' / 'teach.md').read_text().count('| `port` |') == 1


@pytest.fixture
def teach_node(monkeypatch, tmp_path):
    """Run a teach node in this process, on a free port, with no dmp_server anywhere."""
    from conftest import isolate_dds
    isolate_dds(monkeypatch)
    context = rclpy.Context()
    rclpy.init(context=context, args=['--ros-args', '--disable-rosout-logs'])
    from etdmp_ros.nodes.teach import TeachNode
    from rclpy.parameter import Parameter
    # No dmp_server in this domain: a short look for its services says so as well as 2 s.
    monkeypatch.setattr('etdmp_ros.nodes.teach.SERVICE_WAIT', 0.2)
    node = TeachNode(context=context, parameter_overrides=[
        Parameter('port', value=0), Parameter('report_timeout', value=1.0)])
    yield node
    node.stop()
    node.destroy_node()
    context.try_shutdown()


def _http(url, body=None, content_type='application/json', host=None):
    data = None if body is None else (body if isinstance(body, bytes) else
                                      json.dumps(body).encode())
    headers = {'Content-Type': content_type} if data is not None else {}
    if host:
        headers['Host'] = host
    try:
        with urllib.request.urlopen(urllib.request.Request(url, data, headers), timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()


def test_the_teach_node_declares_its_description_and_serves_its_page(teach_node):
    spec = system.node('teach')
    declared = set(teach_node._parameters) - {'use_sim_time', 'start_type_description_service'}
    assert declared == {p.name for p in spec.all_parameters}
    assert teach_node.get_parameter('address').value == '127.0.0.1'
    url = teach_node.url
    assert url.startswith('http://localhost:')
    for path, kind in (('', b'<canvas id="draw"'), ('teach.js', b"'use strict'"),
                       ('teach.css', b'canvas#draw')):
        status, body = _http(url + path)
        assert status == 200 and kind in body, path
    status, body = _http(url + 'api/config')
    config = json.loads(body)
    assert config['canvas'] == {'width': 640, 'height': 480, 'metres': 0.4}
    assert config['max_points'] == limits.MAX_DRAWN_POINTS
    status, _ = _http(url + 'api/camera.jpg')
    assert status == 503   # no camera here
    assert json.loads(_http(url + 'api/overlay')[1])['size'] is None


def test_the_teach_node_answers_bad_requests_with_the_reason(teach_node):
    url = teach_node.url
    cases = [   # (body, content type, status, reason)
        (request('../x'), 'application/json', 422, "skill name '../x' is not valid"),
        (request('Z', []), 'application/json', 422, 'nothing drawn'),
        (b'{"name": "Z", "strokes": [[[NaN, 1, 2]]]}', 'application/json', 400,
         'NaN is not a number JSON allows'),
        (b'{"name": ', 'application/json', 400, 'not valid JSON'),
        (b'\xff\xfe', 'application/json', 400, 'not valid JSON'),
        (request('Z'), 'text/plain', 415, 'application/json'),
        (json.dumps(request('Z', [[[1.5, 2.5, 3.5]] * 1_000_000])).encode(), 'application/json',
         413, 'larger than MAX_TEACH_REQUEST_BYTES'),
        (request('Z'), 'application/json', 503, 'is not offered: is dmp_server running'),
    ]
    for body, kind, status, reason in cases:
        got, answer = _http(url + 'api/teach', body, kind)
        answer = json.loads(answer)
        assert (got, answer['ok']) == (status, False), (reason, got, answer)
        assert reason in answer['error'], answer['error']
    for body, reason in (({'name': 'Z', 'duration': -1}, 'duration must be a number'),
                         ({'name': 'Z', 'duration': 'x'}, 'duration must be a number'),
                         ({'name': '../x'}, 'is not valid'),
                         ({'name': 'Z'}, 'is not offered')):
        got, answer = _http(url + 'api/write', body)
        assert reason in json.loads(answer)['error'], (body, answer)
    # A page served to this machine only answers to this machine's names (DNS rebinding).
    status, body = _http(url, host='attacker.example')
    assert status == 403 and b'localhost only' in body


def _raw(url, data):
    """Send raw bytes to the node's port; return the answer's status and body."""
    port = int(url.rsplit(':', 1)[1].strip('/'))
    with socket.create_connection(('127.0.0.1', port), timeout=10) as connection:
        connection.sendall(data)
        answer = b''
        while chunk := connection.recv(65536):
            answer += chunk
    head, _, body = answer.partition(b'\r\n\r\n')
    return int(head.split()[1]), body


def _post(path, body, host='localhost'):
    return (f'POST {path} HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n'
            f'Content-Length: {len(body)}\r\nConnection: close\r\n\r\n').encode() + body


def _get(path, *headers):
    lines = ''.join(f'{h}\r\n' for h in headers)
    return f'GET {path} HTTP/1.1\r\n{lines}Connection: close\r\n\r\n'.encode()


#: Requests that broke the page's server (HTTP 500 and a traceback of 10-27 lines each), or
#: were let through: (what, raw request, status, fragment of the answer).
HTTP_ATTACKS = [
    ('[ x 100000 to /api/teach', _post('/api/teach', b'[' * 100_000), 400,
     'nests lists or objects deeper'),
    ('{"a": x 50000 to /api/write', _post('/api/write', b'{"a": ' * 50_000), 400,
     'nests lists or objects deeper'),
    ('Host ::1 without brackets', _get('/api/config', 'Host: ::1'), 400,
     "the Host header '::1' is not host[:port]"),
    ('Host localhost:8080:evil', _get('/api/config', 'Host: localhost:8080:evil'), 400,
     'is not host[:port]'),
    ('Host with port 99999', _get('/api/config', 'Host: 127.0.0.1:99999'), 400,
     'is not host[:port]'),
    ('Host [::1 unclosed (was let through)', _get('/api/config', 'Host: [::1'), 400,
     'is not host[:port]'),
    ('Host attacker.example', _get('/api/config', 'Host: attacker.example'), 403,
     'localhost only'),
    ('two Host headers', _get('/api/config', 'Host: localhost', 'Host: evil.example'), 400,
     "Duplicate 'Host'"),
    ('a header of 100 kB', _get('/', 'Host: localhost', 'X: ' + 'a' * 100_000), 400,
     'Got more than'),
]


@pytest.mark.parametrize('what, data, status, fragment', HTTP_ATTACKS,
                         ids=[row[0] for row in HTTP_ATTACKS])
def test_malformed_requests_get_a_4xx_and_one_log_line(teach_node, capfd, what, data, status,
                                                       fragment):
    capfd.readouterr()
    got, body = _raw(teach_node.url, data)
    assert (got, fragment in body.decode()) == (status, True), body[:300]
    time.sleep(0.1)
    log = capfd.readouterr().err
    assert 'Traceback' not in log, log
    lines = [line for line in log.splitlines() if 'teaching page' in line]
    assert len(lines) == 1 and '[WARN]' in lines[0], log
    for good in ('Host: localhost:8080', 'Host: [::1]:8080', 'Host: LOCALHOST', 'Host: 127.0.0.1'):
        assert _raw(teach_node.url, _get('/api/config', good))[0] == 200, good


def test_a_failing_handler_is_one_error_line_and_a_json_answer(teach_node, capfd, monkeypatch):
    def broken():
        raise KeyError('a bug')
    monkeypatch.setattr(teach_node, 'config', broken)
    capfd.readouterr()
    status, body = _http(teach_node.url + 'api/config')
    assert status == 500
    assert json.loads(body) == {'ok': False, 'error': "internal error: KeyError: 'a bug'"}
    time.sleep(0.1)
    log = capfd.readouterr().err
    lines = [line for line in log.splitlines() if 'teaching page' in line]
    assert 'Traceback' not in log and len(lines) == 1 and '[ERROR]' in lines[0], log


def test_a_port_in_use_is_a_clear_start_up_error(teach_node, monkeypatch):
    from etdmp_ros.nodes.teach import InvalidConfiguration, TeachNode
    from rclpy.parameter import Parameter
    port = int(teach_node.url.rsplit(':', 1)[1].strip('/'))
    with pytest.raises(InvalidConfiguration):
        TeachNode(context=teach_node.context, parameter_overrides=[
            Parameter('port', value=port)])
    with socket.create_connection(('127.0.0.1', port), timeout=5):
        pass   # the first node still serves
