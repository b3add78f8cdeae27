"""
teach: the teaching page. Draw a movement in a browser, teach it, watch the UR10 write it.

``ros2 run etdmp_ros teach`` serves http://localhost:8080 (parameters ``port`` and ``address``:
this machine only by default); ``make teach`` runs it beside the whole simulated system, and
``ros2 launch etdmp_ros etdmp.launch.py teach:=true`` starts it with the launch file. The page
and its script are package files (``etdmp_ros/teach_page/``); what the node does with a drawing
is ROS-free (:mod:`etdmp_ros.skills.teaching`); the server is aiohttp in a thread of its own
(:mod:`etdmp_ros.nodes._web`). docs/teach.md says what the page shows and sends.

Interfaces (docs/teach.md, "How the page talks to dmp_server"): every request carries its own
skill name and settings, so that the page and other clients of dmp_server cannot mix, and no
parameter of dmp_server changes:

- teaching: dmp_server's task plane, ``formulation`` and ``n_basis`` (read, so the drawing is
  checked and shown exactly as dmp_server will learn it), then dmp_server's ``~/teach`` service
  with the name and the drawing's base_link samples; its answer says what it learned, or why
  not;
- writing: dmp_server's ``~/generalize_with`` service with the skill, the duration and
  ``execute`` true, from the pen to the perceived goal; its answer says what it planned, or why
  not;
- the camera view: ``/camera/camera/color/image_raw`` (raw bytes, best effort: never able to
  hold the camera's publisher back) and its ``camera_info``, the plan on ``/etdmp/path``, the
  pen trace (``trace_source``), the controller's status. The image and the trace are subscribed
  only while a page watches (asked for an image in the last ``watch_timeout`` seconds): with no
  page open the node receives nothing but log lines, plans and status changes.

Threads: the executor (``_spin.run``) runs the subscriptions and a 2 Hz timer that subscribes
and unsubscribes the camera view; the web server's loop thread and its workers serve the page
and wait for dmp_server's answers (one teaching or writing at a time from this page).
"""

import asyncio
import contextlib
from dataclasses import dataclass
import importlib.resources
import struct
import threading
import time

from aiohttp import web
import cv2
from etdmp_ros import limits
from etdmp_ros.dmp import builtin_demo, learn
from etdmp_ros.geometry.camera import CameraPose
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.nodes._web import one_line, WebServer
from etdmp_ros.ros import system
from etdmp_ros.ros.conversions import image_from_cdr, intrinsics_from_camera_info, path_from_cdr
from etdmp_ros.ros.conversions._cdr import CdrReader
from etdmp_ros.ros.node_parameters import TeachParameters
from etdmp_ros.ros.parameters import declared_settings, InvalidConfiguration
from etdmp_ros.ros.spin import run
from etdmp_ros.skills.library import check_skill_name
from etdmp_ros.skills.teaching import (Canvas, decode_json, generalizations, is_local,
                                       learn_drawing, LOCAL_NAMES, MalformedRequest,
                                       parse_drawing, project, taught_path, TeachInputError,
                                       Trace)
from geometry_msgs.msg import PointStamped, PoseStamped
from nav_msgs.msg import Path
import numpy as np
from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

NODE_NAME = 'teach'
DESCRIPTION = system.node(NODE_NAME)
PAGE_FILES = {'/': ('index.html', 'text/html'), '/teach.js': ('teach.js', 'text/javascript'),
              '/teach.css': ('teach.css', 'text/css')}
COLOR_TOPIC = 'camera/camera/color/image_raw'
INFO_TOPIC = 'camera/camera/color/camera_info'
TRACE_TOPICS = {'ground_truth': 'ur10_sim/ground_truth/tool_tip', 'tool_pose': 'etdmp/tool_pose'}
#: Seconds between two looks at whether a page watches (subscribing or unsubscribing the view).
WATCH_PERIOD = 0.5
#: Longest wait for a dmp_server service to be offered (s).
SERVICE_WAIT = 2.0
#: A request that may be repeated (reading parameters, teaching) is sent again after this long
#: without an answer (s).
RETRY_PERIOD = 1.0
#: Plan poses projected for the page at most.
PLAN_POINTS = 600
_LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
_VIEW = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
TRACE_TYPES = {'ground_truth': PointStamped, 'tool_pose': PoseStamped}


class Unavailable(Exception):
    """dmp_server (or what it needs) does not answer; the message says what (HTTP 503)."""


class Busy(Exception):
    """Another teaching or writing is under way (HTTP 409)."""


@dataclass(frozen=True)
class Settings:
    """The node's parameters, validated."""

    port: int
    address: str
    canvas: Canvas
    dmp_server: str
    report_timeout: float
    camera_period: float
    jpeg_quality: int
    watch_timeout: float
    trace_topic: str
    trace_type: type
    camera: CameraPose

    @classmethod
    def from_values(cls, values):
        """Build from {parameter name: value}; raise ValueError saying what is wrong."""
        p = TeachParameters.from_values(values)     # each value by its description
        name = p.dmp_server
        if not name or not all(part and (part[0].isalpha() or part[0] == '_') and
                               part.replace('_', 'a').isalnum() for part in name.split('/')):
            raise ValueError(f'dmp_server must be a node name such as dmp_server, got {name!r}')
        return cls(p.port, p.address, Canvas(p.canvas_width), name, p.report_timeout,
                   1.0 / p.camera_rate, p.jpeg_quality, p.watch_timeout,
                   TRACE_TOPICS[p.trace_source], TRACE_TYPES[p.trace_source],
                   CameraPose(p.camera_position, p.camera_orientation))


def point_from_cdr(data):
    """
    Return the position (x, y, z) of a serialized PointStamped or PoseStamped.

    Both are a std_msgs/Header followed by three float64: the point, or the pose's position.
    """
    reader = CdrReader(data)
    reader.int32(), reader.uint32(), reader.string()
    offset = 4 + reader.offset + (-reader.offset % 8)
    try:
        return struct.unpack_from(reader.order + '3d', data, offset)
    except struct.error:
        raise ValueError('serialized message ends too early') from None


def _message(err):
    text = str(err)
    return text if len(text) <= 2 * limits.MAX_REASON_CHARS else \
        text[:2 * limits.MAX_REASON_CHARS - 3] + '...'


class TeachNode(Node):
    """The teaching page's node: a web server beside subscriptions and dmp_server's clients."""

    def __init__(self, **kwargs):
        """Declare the parameters, subscribe, start the web server."""
        super().__init__(NODE_NAME, **kwargs)
        log = self.get_logger()
        self._settings = declared_settings(self, DESCRIPTION, Settings.from_values)
        settings = self._settings
        self._busy = threading.Lock()
        self._stopping = threading.Event()
        self._frame = None            # the latest colour image: (CDR bytes, received)
        self._jpeg = (None, None, 0.0)   # (JPEG, the frame's received, encoded at)
        self._jpeg_lock = threading.Lock()
        self._intrinsics = None
        self._plan = (0, np.zeros((0, 3)))   # (number, base_link positions)
        self._projected_plan = (None, [])
        self._status = ''
        self._trace = Trace()
        self._watched_until = 0.0
        self._view = []               # the subscriptions made while a page watches
        self.frames_received = 0
        self.create_subscription(Path, 'etdmp/path', self._on_path, _LATCHED, raw=True)
        self.create_subscription(String, 'etdmp/controller/status', self._on_status, _LATCHED)
        server = settings.dmp_server
        self._get_client = self.create_client(GetParameters, f'{server}/get_parameters')
        self._teach_client = self.create_client(SetParametersAtomically, f'{server}/teach')
        self._write_client = self.create_client(SetParametersAtomically,
                                                f'{server}/generalize_with')
        self.create_timer(WATCH_PERIOD, self._update_view)
        threading.Thread(target=_warm_up, daemon=True, name='warm_up').start()
        self._web = WebServer(make_app(self), settings.address, settings.port, self._web_log)
        try:
            self._web.start()
        except OSError as err:
            log.fatal(f'cannot serve the teaching page on {settings.address}:{settings.port}: '
                      f'{err.strerror or err}')
            raise InvalidConfiguration(str(err)) from None
        log.info(f'teaching page on {self._web.url} (dmp_server: /{server})')

    @property
    def url(self):
        """Return the page's address."""
        return self._web.url

    @property
    def loopback(self):
        """Return True if the page is served to this machine only."""
        return self._settings.address in LOCAL_NAMES

    def said(self, request, status, text):
        """Log the answer ``status`` (4xx: WARN, 5xx: ERROR) to ``request``, one line."""
        self._web_log('warn' if status < 500 else 'error',
                      f'{request.method} {request.path}: {status}: {text}')

    def _web_log(self, level, text):
        text = f'teaching page: {one_line(text, 2 * limits.MAX_REASON_CHARS)}'
        # Two call sites: rclpy refuses a call site whose severity changes between calls.
        if level == 'warn':
            self.get_logger().warn(text)
        else:
            self.get_logger().error(text)

    def stop(self):
        """Stop the web server (called before the node is destroyed)."""
        self._stopping.set()
        self._web.stop()

    # -- subscriptions ----------------------------------------------------------------------

    def _on_path(self, data):
        try:
            positions = path_from_cdr(data)[3]
        except ValueError as err:
            self.get_logger().warn(f'/etdmp/path: unreadable: {err}', throttle_duration_sec=5.0)
            return
        self._plan = (self._plan[0] + 1, positions)

    def _on_status(self, msg):
        self._status = msg.data

    def _on_image(self, data):
        self._frame = (data, time.monotonic())
        self.frames_received += 1

    def _on_info(self, msg):
        try:
            self._intrinsics = intrinsics_from_camera_info(msg)
        except ValueError as err:
            self.get_logger().warn(f'camera_info: {err}', throttle_duration_sec=5.0)

    def _on_trace(self, data):
        try:
            point = point_from_cdr(data)
        except ValueError:
            return
        self._trace.add(point)

    def _watch(self):
        self._watched_until = time.monotonic() + self._settings.watch_timeout

    def _update_view(self):
        """Subscribe the camera view while a page watches, unsubscribe it after (executor)."""
        watching = time.monotonic() < self._watched_until
        if watching and not self._view:
            self._view = [
                self.create_subscription(Image, COLOR_TOPIC, self._on_image, _VIEW, raw=True),
                self.create_subscription(self._settings.trace_type,
                                         self._settings.trace_topic, self._on_trace,
                                         QoSProfile(depth=50,
                                                    reliability=ReliabilityPolicy.BEST_EFFORT),
                                         raw=True)]
            if self._intrinsics is None:
                self._view.append(self.create_subscription(CameraInfo, INFO_TOPIC,
                                                           self._on_info, _VIEW))
        elif not watching and self._view:
            for subscription in self._view:
                self.destroy_subscription(subscription)
            self._view = []
            self._frame = None

    # -- dmp_server ---------------------------------------------------------------------------

    def _call(self, client, request, what, retry=False):
        """
        Call a service and wait for the answer (at most report_timeout); Unavailable if none.

        ``retry``: ask again every RETRY_PERIOD while no answer came, for requests that may be
        repeated (parameters): a service seen a moment ago may not be matched to this client's
        answers yet, and the middleware then drops its answer.
        """
        service = self.resolve_service_name(client.srv_name)
        if not client.wait_for_service(timeout_sec=SERVICE_WAIT):
            raise Unavailable(f'{service} is not offered: is dmp_server running (node '
                              f'/{self._settings.dmp_server})?')
        future, sent = client.call_async(request), time.monotonic()
        deadline = sent + self._settings.report_timeout
        while not future.done():
            now = time.monotonic()
            if self._stopping.is_set() or now > deadline:
                client.remove_pending_request(future)
                if self._stopping.is_set():
                    raise Unavailable('the teach node is stopping')
                raise Unavailable(f'no answer to {what} from {service} within '
                                  f'{self._settings.report_timeout:g} s')
            if retry and now - sent > RETRY_PERIOD:
                client.remove_pending_request(future)
                future, sent = client.call_async(request), now
            time.sleep(0.005)
        return future.result()

    def _ask(self, client, what, retry, **arguments):
        """
        Call one of dmp_server's request services with ``arguments``; return its answer.

        The answer is a SetParametersResult: ``successful`` and dmp_server's ``reason``.
        """
        request = SetParametersAtomically.Request(parameters=[
            Parameter(name, value=value).to_parameter_msg()
            for name, value in arguments.items()])
        return self._call(client, request, what, retry=retry).result

    def _server_plane(self):
        """Return (TaskPlane with dmp_server's scale, formulation, n_basis) from dmp_server."""
        names = ['task_plane.origin', 'task_plane.x_axis', 'task_plane.y_axis',
                 'task_plane.scale', 'formulation', 'n_basis']
        response = self._call(self._get_client, GetParameters.Request(names=names),
                              'reading parameters', retry=True)
        values = dict(zip(names, (parameter_value_to_python(v) for v in response.values)))
        if len(values) != len(names):
            raise Unavailable(f'dmp_server did not give its parameters {", ".join(names)}')
        plane = TaskPlane.create(values['task_plane.origin'], values['task_plane.x_axis'],
                                 values['task_plane.y_axis'], values['task_plane.scale'])
        return plane, values['formulation'], values['n_basis']

    @contextlib.contextmanager
    def _exclusive(self):
        if not self._busy.acquire(blocking=False):
            raise Busy('the page is busy with another teaching or writing: try again when it '
                       'is done')
        try:
            yield
        finally:
            self._busy.release()

    # -- what the page asks ------------------------------------------------------------------

    def config(self):
        """Return what the page needs to know: the canvas, the limits, the camera period."""
        canvas = self._settings.canvas
        return {'canvas': {'width': canvas.width_px, 'height': canvas.height_px,
                           'metres': canvas.width_m},
                'max_points': limits.MAX_DRAWN_POINTS, 'max_strokes': limits.MAX_STROKES,
                'camera_period': self._settings.camera_period,
                'dmp_server': self._settings.dmp_server}

    def teach(self, data):
        """
        Teach a drawing to dmp_server; return what the page shows (blocking).

        Raises TeachInputError (the drawing or dmp_server's refusal), Unavailable, Busy.
        """
        canvas = self._settings.canvas
        drawing = parse_drawing(data, canvas)
        with self._exclusive():
            started = time.monotonic()
            plane, formulation, n_basis = self._server_plane()
            try:
                demo, skill = learn_drawing(drawing, canvas, plane, formulation, n_basis)
            except TeachInputError as err:
                raise TeachInputError(f'not taught: {err} (checked here as dmp_server checks '
                                      'it; nothing was sent)') from None
            shown = generalizations(skill, canvas, plane)
            positions, t = taught_path(drawing, canvas, plane)
            # Repeated if unanswered: teaching the same again replaces it with the same.
            answer = self._ask(self._teach_client, 'teaching', True, name=drawing.name,
                               t=t.tolist(), positions=positions.ravel().tolist(),
                               recorded_dim='2d')
            if not answer.successful:
                raise TeachInputError(f'dmp_server: {answer.reason}')
            text = answer.reason
            elapsed = time.monotonic() - started
        self.get_logger().info(f'taught {drawing.name!r} ({demo.n_samples} samples, '
                               f'{demo.duration:.2f} s, {drawing.strokes} stroke(s)) in '
                               f'{elapsed * 1e3:.0f} ms')
        return {'ok': True, 'message': f'dmp_server {text}', 'seconds': round(elapsed, 3),
                'skill': {'name': drawing.name, 'samples': demo.n_samples,
                          'duration': round(demo.duration, 3), 'strokes': drawing.strokes,
                          **shown}}

    def write(self, data):
        """
        Have the robot write skill ``data['name']`` from the pen to the perceived goal (blocking).

        ``data['duration']``: the plan's duration in seconds, or null for the drawing's own
        speed. Raises TeachInputError (bad input, dmp_server's refusal), Unavailable, Busy.
        """
        if not isinstance(data, dict):
            raise TeachInputError('the request must be a JSON object {"name": ...}')
        try:
            name = check_skill_name(data.get('name'))
        except ValueError as err:
            raise TeachInputError(str(err)) from None
        duration = data.get('duration')
        if duration is None:
            duration = 0.0
        if not isinstance(duration, (int, float)) or isinstance(duration, bool) or \
                not 0.0 <= duration <= limits.MAX_DEMO_DURATION:
            raise TeachInputError(f'duration must be a number of seconds from 0 to '
                                  f'{limits.MAX_DEMO_DURATION:g} (or empty: as drawn), got '
                                  f'{duration!r}')
        with self._exclusive():
            started = time.monotonic()
            self._trace.clear()
            self._watch()
            # Never repeated: a second request would write it twice.
            answer = self._ask(self._write_client, 'writing', False, skill=name,
                               duration=float(duration), execute=True)
            elapsed = time.monotonic() - started
        if not answer.successful:
            raise TeachInputError(f'dmp_server planned nothing: {answer.reason}')
        return {'ok': True, 'seconds': round(elapsed, 3),
                'message': f'writing {name!r}: dmp_server {answer.reason}, from the pen to the '
                           'goal marker'}

    def camera_jpeg(self):
        """
        Return the latest camera image as JPEG bytes, None before the first one.

        Encoded again at most once a camera period; the page counts as watching.
        """
        self._watch()
        frame = self._frame
        if frame is None:
            return None
        with self._jpeg_lock:
            jpeg, received, encoded = self._jpeg
            now = time.monotonic()
            if jpeg is not None and (received == frame[1] or
                                     now - encoded < self._settings.camera_period):
                return jpeg
            pixels = image_from_cdr(frame[0])
            reader = CdrReader(frame[0])
            reader.int32(), reader.uint32(), reader.string(), reader.uint32(), reader.uint32()
            if reader.string() == 'rgb8':
                pixels = cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_RGB2BGR)
            ok, encoded_image = cv2.imencode('.jpg', np.ascontiguousarray(pixels),
                                             [cv2.IMWRITE_JPEG_QUALITY,
                                              self._settings.jpeg_quality])
            if not ok:
                return jpeg
            self._jpeg = (encoded_image.tobytes(), frame[1], now)
            return self._jpeg[0]

    def overlay(self):
        """Return the plan and the pen trace in camera pixels, and the controller's status."""
        self._watch()
        intrinsics, camera = self._intrinsics, self._settings.camera
        result = {'status': self._status, 'size': None, 'plan': [], 'trace': []}
        if intrinsics is None:
            return result
        result['size'] = [intrinsics.width, intrinsics.height]
        number, positions = self._plan
        if self._projected_plan[0] != number:
            step = max(1, len(positions) // PLAN_POINTS)
            self._projected_plan = (number, project(positions[::step], intrinsics, camera))
        result['plan'] = self._projected_plan[1]
        result['trace'] = project(self._trace.points(), intrinsics, camera)
        return result


def _warm_up():
    """Have numba load (or compile) the rollouts a first teaching uses, off the page's path."""
    skill = learn(builtin_demo('G'))
    starts = np.stack([skill.start, 2.0 * skill.goal - skill.start])
    for method in ('etdmp', 'dmp'):
        try:
            skill.generalize(starts, skill.goal, method=method)
        except ValueError:
            pass


# ------------------------------------------------------------------------------ the web side

def _error(status, text):
    return web.json_response({'ok': False, 'error': text}, status=status)


def make_app(node):
    """Return the aiohttp application of the page: its files and its JSON API (docs/teach.md)."""
    page = importlib.resources.files('etdmp_ros') / 'teach_page'
    files = {route: ((page / name).read_bytes(), kind)
             for route, (name, kind) in PAGE_FILES.items()}

    def refused(request, status, text):
        node.said(request, status, text)
        return _error(status, text)

    @web.middleware
    async def guarded(request, handler):
        # A page served to this machine only answers to this machine's names: a web site that
        # points its own name at 127.0.0.1 (DNS rebinding) gets nothing. And whatever goes
        # wrong in a handler is one line in the log and a JSON answer, never a traceback.
        try:
            local = is_local(request.headers.get('Host'))
        except MalformedRequest as err:
            return refused(request, 400, str(err))
        if node.loopback and not local:
            node.said(request, 403, 'Host is not this machine')
            return web.Response(status=403, text='this page answers on localhost only')
        try:
            return await handler(request)
        except web.HTTPException:
            raise   # aiohttp's own answers: 404, 405
        except Exception as err:   # noqa: B902 - a bug must not be a traceback per request
            return refused(request, 500, f'internal error: {type(err).__name__}: '
                                         f'{_message(err)}')

    async def page_file(request):
        body, kind = files[request.path]
        return web.Response(body=body, content_type=kind, headers={'Cache-Control': 'no-cache'})

    def post(action):
        async def handler(request):
            if request.content_type != 'application/json':
                return refused(request, 415, 'send the request as application/json (as the '
                                             'page does)')
            try:
                body = await request.read()
            except web.HTTPRequestEntityTooLarge:
                return refused(request, 413, f'the request is larger than '
                                             f'MAX_TEACH_REQUEST_BYTES = '
                                             f'{limits.MAX_TEACH_REQUEST_BYTES} bytes (a drawing '
                                             f'may have {limits.MAX_DRAWN_POINTS} points): '
                                             'nothing was taught')
            try:
                data = decode_json(body)
            except MalformedRequest as err:
                return refused(request, 400, _message(err))
            loop = asyncio.get_running_loop()
            try:
                return web.json_response(await loop.run_in_executor(None, action, data))
            except TeachInputError as err:
                return refused(request, 422, _message(err))
            except Busy as err:
                return refused(request, 409, str(err))
            except Unavailable as err:
                return refused(request, 503, str(err))
        return handler

    async def config(request):
        return web.json_response(node.config())

    async def camera(request):
        jpeg = await asyncio.get_running_loop().run_in_executor(None, node.camera_jpeg)
        if jpeg is None:
            return web.Response(status=503, text='no camera image yet (is ur10_sim running?)',
                                headers={'Cache-Control': 'no-store'})
        return web.Response(body=jpeg, content_type='image/jpeg',
                            headers={'Cache-Control': 'no-store'})

    async def overlay(request):
        return web.json_response(node.overlay(), headers={'Cache-Control': 'no-store'})

    app = web.Application(client_max_size=limits.MAX_TEACH_REQUEST_BYTES,
                          middlewares=[guarded])
    for route in files:
        app.router.add_get(route, page_file)
    app.router.add_get('/api/config', config)
    app.router.add_post('/api/teach', post(node.teach))
    app.router.add_post('/api/write', post(node.write))
    app.router.add_get('/api/camera.jpg', camera)
    app.router.add_get('/api/overlay', overlay)
    return app


def main(args=None):
    """Run the teach node until Ctrl-C (or SIGTERM)."""
    return run(lambda nodes: nodes.append(TeachNode()), NODE_NAME, args,
               startup_errors=(InvalidConfiguration,))


if __name__ == '__main__':
    main()
