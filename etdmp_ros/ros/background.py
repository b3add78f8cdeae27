"""
An rclpy node in a context of its own, spun by a background thread: for tools, tests, the demo.

It spins with the executor every node program uses (:mod:`etdmp_ros.ros.spin`) and loads the
package's DDS profile first, so what it measures is what a node would see.
"""

from __future__ import annotations

import threading

from etdmp_ros.ros import spin as _spin
import rclpy
from rclpy.signals import SignalHandlerOptions


class BackgroundNode:
    """
    An rclpy node in a context of its own, spun by a background thread (for tools and tests).

    Create subscriptions and clients on ``self.node``, then call :meth:`start`; :meth:`close`
    stops the thread and shuts the context down. ``domain_id`` None means ROS_DOMAIN_ID.
    """

    def __init__(self, name: str, domain_id: int | None = None) -> None:
        """Create the context and the node (not spinning yet)."""
        self.context = rclpy.Context()
        with _spin.dds_settings():
            if domain_id is None:
                rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
            else:
                rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO,
                           domain_id=int(domain_id))
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = _spin.make_executor(self.context)
        self._thread = threading.Thread(target=self._spin, daemon=True, name=f'{name}_spin')

    def start(self) -> BackgroundNode:
        """Start spinning in the background thread; return self."""
        self.executor.add_node(self.node)
        self._thread.start()
        return self

    def _spin(self) -> None:
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=_spin.SLICE)
            except Exception:   # noqa: B902
                if self.context.ok():
                    raise       # a callback failed: said (threading.excepthook), not hidden
                break           # the context was shut down while waiting

    def close(self) -> None:
        """Stop spinning, shut the context down and destroy the node."""
        rclpy.shutdown(context=self.context)
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        self.node.destroy_node()
