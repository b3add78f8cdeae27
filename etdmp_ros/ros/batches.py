"""
A topic read in batches, on a thread of its own, instead of message by message by the executor.

rclpy's executors hand a subscription's messages to Python one at a time. The EventsExecutor
dispatches each through its C++ event queue (the Global Interpreter Lock taken, the
subscription's attributes looked up, one take): about 40 microseconds a message on an AMD EPYC
of this machine kind even for a callback that does nothing, and as much for an event whose
message an earlier callback already took. 13 000 joint states a second for other joints, from
another process, kept the controller's real-time thread busy all the time and the simulation
braked for want of commands. A :class:`TopicBatches` waits on its subscription itself and takes
all that queued in one go, at most once every ``min_interval`` seconds: on the same machine
the reading process then spent 0.41 instead of 0.72 cores on such a flood, Fast DDS's UDP
reception (about 0.3) included (``make bench-flood``, docs/controller.md). Messages arriving
slower than that are taken as each arrives, as before.

The subscription belongs to a hidden node of the same context and namespace that no executor
spins (its name starts with an underscore: ``ros2 node list --all`` shows it). Remappings given
for the whole process apply to it; one given for the owning node only does not.
"""

from __future__ import annotations

from collections.abc import Callable
import threading
import time
from typing import Any

from etdmp_ros.ros.spin import set_realtime_priority
import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile

#: ns a wait lasts at most: how soon :meth:`TopicBatches.stop` is noticed.
_WAIT_NS = 50_000_000


class TopicBatches:
    """
    Take serialized messages of ``topic`` in batches and hand each batch to ``on_batch``.

    ``on_batch(batch)`` gets a list of the serialized messages (bytes, oldest first, at most
    ``limit``) in the thread of :meth:`start`. :meth:`take` takes what queued from any thread
    (e.g. a watchdog that must see queued messages before it calls them lost). ``lock``: held
    while a batch is taken and handed over; the owner's, so that a batch it takes itself under
    it is never handled before an older one.
    """

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: QoSProfile,
                 on_batch: Callable[[list[bytes]], None], min_interval: float,
                 limit: int, lock: threading.Lock | None = None) -> None:
        """Create the hidden node and its subscription; nothing is taken until :meth:`start`."""
        self.msg_type, self.on_batch = msg_type, on_batch
        self.min_interval, self.limit = min_interval, limit
        self.lock = lock or threading.Lock()
        self.node = rclpy.create_node(
            f'_{node.get_name()}_{topic.strip("/").replace("/", "_")}', context=node.context,
            namespace=node.get_namespace(), start_parameter_services=False,
            enable_rosout=False)
        self.subscription = self.node.create_subscription(msg_type, topic, _unused, qos,
                                                          raw=True)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def take(self) -> list[bytes]:
        """Return the messages queued now (at most ``limit``), oldest first."""
        batch = []
        handle = self.subscription.handle
        with handle:
            for _ in range(self.limit):
                taken = handle.take_message(self.msg_type, True)
                if taken is None:
                    break
                batch.append(taken[0])
        return batch

    def start(self, priority: int = 0) -> None:
        """Start the thread (at SCHED_FIFO ``priority`` where allowed, 0: normal)."""
        self._thread = threading.Thread(target=self._run, args=(priority,), daemon=True,
                                        name=self.node.get_name())
        self._thread.start()

    def stop(self) -> None:
        """End the thread and destroy the hidden node (again: nothing)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.node.destroy_node()

    def _run(self, priority: int) -> None:
        if priority:
            set_realtime_priority(priority)
        context = self.node.context
        handle = context.handle
        assert handle is not None                   # a context of a node is initialized
        with handle, self.subscription.handle:
            wait_set = _rclpy.WaitSet(1, 0, 0, 0, 0, 0, handle)
        last = 0.0
        while not self._stop.is_set() and context.ok():
            try:
                with handle, self.subscription.handle:
                    wait_set.clear_entities()
                    wait_set.add_subscription(self.subscription.handle)
                    wait_set.wait(_WAIT_NS)
                with self.lock:
                    batch = self.take()
                    if batch:
                        self.on_batch(batch)
            except (InvalidHandle, _rclpy.RCLError):
                break       # the context or the node went away: nothing more to take
            # A batch at most every min_interval: a flood queues meanwhile, taken in one go.
            rest = last + self.min_interval - time.monotonic()
            if rest > 0:
                time.sleep(rest)
            last = time.monotonic()


def _unused(message: bytes) -> None:
    """Stand in for a callback: no executor spins the hidden node."""
