"""
An aiohttp application served by a thread of its own, beside a node's executor (no ROS here).

Why aiohttp (docs/teach.md#the-web-stack): a small, well-kept asyncio HTTP server with a
request body limit applied before anything is parsed (``client_max_size``), keep-alive,
graceful shutdown and a stable API since 2017; the standard library's ``http.server`` is
"not recommended for production" and would need the body limit, the thread per connection and
the shutdown written here. The server's event loop runs in :class:`WebServer`'s thread; what a
handler must wait for (a ROS service, dmp_server's report) runs in the loop's thread pool, so
the loop stays free and the node's executor is never blocked by the web side.
"""

import asyncio
from concurrent.futures import ThreadPoolExecutor
import logging
import threading

from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError

#: Threads for the handlers' blocking work (ROS calls, JPEG encoding).
WORKERS = 4
#: Longest wait for the server to bind or to shut down (s).
START_TIMEOUT = 10.0
#: Time open requests get to finish when the server stops (s).
SHUTDOWN_TIMEOUT = 1.0
#: Longest text of one log line about a request (characters).
MAX_LOG_CHARS = 300


def one_line(text, limit=MAX_LOG_CHARS):
    """Return ``text`` on one line, cut to ``limit`` characters."""
    text = ' '.join(str(text).split())
    return text if len(text) <= limit else text[:limit - 3] + '...'


class _OneLine(logging.Handler):
    """
    Hand aiohttp's server log to ``log(level, text)`` as one line, without a traceback.

    aiohttp logs a request it cannot parse (a malformed request line or header, a duplicate
    Host header, a header longer than 8190 bytes) with the exception's traceback, some 10 lines
    per request, before it answers 400. The client's mistake is one WARN line here
    ('warn'); anything else aiohttp reports is one ERROR line ('error').
    """

    def __init__(self, log):
        super().__init__(logging.INFO)
        self._log = log

    def emit(self, record):
        err = record.exc_info[1] if record.exc_info else None
        text = record.getMessage()
        if err is not None:
            text = f'{text}: {type(err).__name__}: {err}'
        level = 'warn' if isinstance(err, HttpProcessingError) or \
            record.levelno < logging.ERROR else 'error'
        try:
            self._log(level, one_line(text))
        except Exception:   # noqa: B902 - logging must never take the server down
            pass


class WebServer:
    """
    Serve an aiohttp ``app`` on ``host``:``port`` from a thread with an asyncio loop of its own.

    :meth:`start` returns once the socket is bound (raising the OSError of a port in use);
    :attr:`port` is then the bound port (``port=0`` picks a free one). :meth:`stop` closes the
    connections and ends the thread.
    """

    def __init__(self, app, host, port, log=None):
        """
        Prepare (nothing is bound yet).

        ``log(level, text)`` ('warn' or 'error') receives what aiohttp itself reports about a
        request, one line each (default: Python's logging, as aiohttp does).
        """
        self.app, self.host, self.port = app, host, int(port)
        self._logger = None
        if log is not None:
            self._logger = logging.getLogger(f'{__name__}.{id(self)}')
            self._logger.propagate = False
            self._logger.setLevel(logging.INFO)
            self._logger.addHandler(_OneLine(log))
        self._loop = None
        self._runner = None
        self._ready = threading.Event()
        self._error = None
        self._thread = threading.Thread(target=self._run, daemon=True, name='web')

    @property
    def url(self):
        """Return the page's address, e.g. ``http://localhost:8080/``."""
        host = 'localhost' if self.host in ('127.0.0.1', '::1', 'localhost') else self.host
        host = f'[{host}]' if ':' in host else host
        return f'http://{host}:{self.port}/'

    def start(self):
        """Bind and start serving in the thread; raise the OSError if binding fails."""
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT):
            raise OSError(f'the web server did not start within {START_TIMEOUT:g} s')
        if self._error is not None:
            raise self._error

    def _run(self):
        loop = self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        workers = ThreadPoolExecutor(WORKERS, thread_name_prefix='web_worker')
        loop.set_default_executor(workers)
        try:
            loop.run_until_complete(self._bind())
        except OSError as err:
            self._error = err
            self._ready.set()
            workers.shutdown(wait=False)
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(self._runner.cleanup())
            # A handler still waiting (for dmp_server) ends by itself: the owner makes its
            # waits return when it stops (TeachNode.stop).
            workers.shutdown(wait=False, cancel_futures=True)
            loop.close()

    async def _bind(self):
        extra = {} if self._logger is None else {'logger': self._logger}
        self._runner = web.AppRunner(self.app, access_log=None, handle_signals=False,
                                     shutdown_timeout=SHUTDOWN_TIMEOUT, **extra)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        try:
            await site.start()
        except OSError:
            await self._runner.cleanup()
            raise
        self.port = self._runner.addresses[0][1]

    def stop(self):
        """Close the server and end its thread (idempotent)."""
        loop = self._loop
        if loop is None or not self._thread.is_alive():
            return
        loop.call_soon_threadsafe(loop.stop)
        self._thread.join(START_TIMEOUT)
