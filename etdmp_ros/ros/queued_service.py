"""
A ROS service served first come first served by a thread of its own, refusing what waited long.

Why not an ordinary rclpy service: its requests wait in the middleware's history, and when more
arrive than the node answers (a burst, or clients that call faster than it plans), the history
overwrites the oldest ones, which are then never answered and nobody is told (rclpy has no
notification of a dropped request). Here the thread takes every waiting request out of the
middleware as soon as it is free, with the time the middleware received it, into its own queue;
a request that has waited longer than ``max_wait`` by the time its turn comes is answered at once
with ``refuse(request, response, waited)`` (for /generalize an empty plan, a cheap answer), the
others with ``handle(request, response)``. Under overload the queue stays about ``max_wait``
deep, every request gets an answer, and the answers are planned or refused within about
``max_wait`` plus one request's work.

The service is not one of the node's entities (not in ``node.services``), so no executor spins
it: it is served whether or not the node is spun, by any executor. It is still the node's
service in the ROS graph (``ros2 service list``, ``ros2 node info``). Its wait set is rclpy's own
(``rclpy.impl``), the one its executors build.
"""

from collections import deque
import threading
import time

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.service import Service
from rclpy.type_support import check_is_valid_srv_type

#: Longest time (s) the thread waits for a request before it checks whether it should stop.
WAIT_SLICE = 0.1


class QueuedService:
    """``srv_type`` service ``name`` of ``node``, served by a thread (above)."""

    def __init__(self, node, srv_type, name, handle, refuse, qos_profile, max_wait, max_queued):
        """Create the service and start serving; ``max_wait`` (s) may be changed later."""
        check_is_valid_srv_type(srv_type)   # also loads its type support
        with node.handle:
            impl = _rclpy.Service(node.handle, srv_type, name, qos_profile.get_c_qos_profile())
        # rclpy's wrapper, for send_response and destroy; never added to the node's entities.
        self._service = Service(impl, srv_type, name, None, node.default_callback_group,
                                qos_profile)
        self._srv_type = srv_type
        self._context = node.context
        self._handle = handle
        self._refuse = refuse
        self.max_wait = max_wait
        self._max_queued = max_queued
        self._queue = deque()   # (request, header, received wall time ns)
        #: Requests answered so far: by ``handle``, by ``refuse`` (waited too long), and those
        #: whose handler raised (answered with an empty response).
        self.answered = {'handled': 0, 'refused': 0, 'failed': 0}
        self._stop = threading.Event()
        self._logger = node.get_logger()
        self._thread = threading.Thread(target=self._serve, daemon=True, name=f'service {name}')
        self._thread.start()

    @property
    def running(self):
        """Whether the service is being served (not stopped)."""
        return not self._stop.is_set()

    def stop(self):
        """Stop serving and destroy the service (requests still queued go unanswered)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        try:
            self._service.destroy()
        except Exception:   # noqa: B902 - already destroyed with its node
            pass

    def _serve(self):
        try:
            with self._context.handle:
                wait_set = _rclpy.WaitSet(0, 0, 0, 0, 1, 0, self._context.handle)
            while not self._stop.is_set() and self._context.ok():
                self._take_all()
                if self._queue:
                    self._answer_next()
                    continue
                with self._service.handle, self._context.handle:
                    wait_set.clear_entities()
                    wait_set.add_service(self._service.handle)
                    wait_set.wait(int(WAIT_SLICE * 1e9))
        except Exception as err:   # noqa: B902 - only at shutdown (an invalid handle or context)
            if not self._stop.is_set() and self._context.ok():
                self._logger.fatal(f'{self._service.srv_name}: no longer served: {err!r}')

    def _take_all(self):
        """Move every request the middleware holds into the queue (up to ``max_queued``)."""
        while len(self._queue) < self._max_queued:
            with self._service.handle:
                request, header = self._service.handle.service_take_request(
                    self._srv_type.Request)
            if header is None:
                return
            # The middleware's receipt time (system clock); 0 where an RMW does not set it.
            received = header.received_timestamp or time.time_ns()
            self._queue.append((request, header, received))

    def _answer_next(self):
        request, header, received = self._queue.popleft()
        waited = max(0.0, (time.time_ns() - received) * 1e-9)
        response = self._srv_type.Response()
        try:
            if waited > self.max_wait:
                response, outcome = self._refuse(request, response, waited), 'refused'
            else:
                response, outcome = self._handle(request, response), 'handled'
        except Exception as err:   # noqa: B902 - a handler's bug must not end the service
            self._logger.error(f'{self._service.srv_name}: request failed: {err!r}')
            response, outcome = self._srv_type.Response(), 'failed'
        self.answered[outcome] += 1
        with self._service.handle:
            self._service.send_response(response, header)
