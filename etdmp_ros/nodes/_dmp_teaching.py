"""
dmp_server's teaching: a demonstration on /etdmp/demonstrations or ~/teach learned as a skill.

A taught demonstration is checked (size, frames, a plan of its own duration), learned into the
skill library and saved to ``skills_dir``; a refused one replaces nothing, and the reason is
logged (ERROR) and returned to a ~/teach client.
"""

from dataclasses import replace
import pathlib

from etdmp_ros import limits
from etdmp_ros.ros import system
from etdmp_ros.ros.conversions import path_from_cdr
from etdmp_ros.ros.events import ERROR
from etdmp_ros.ros.parameters import plain
from etdmp_ros.skills.library import (BASE_FRAMES, check_skill_name, recorded_orientations,
                                      recorded_path_demo, save_skill_demo)
from etdmp_ros.skills.plan_checks import check_usable
from etdmp_ros.skills.planning import bounded
import numpy as np
from rclpy.parameter import parameter_value_to_python

DESCRIPTION = system.node('dmp_server')
#: Where a skill taught at runtime came from (its source in the library): it may be re-taught.
TAUGHT = 'taught on '


def short(text):
    """Return ``text`` cut to MAX_REASON_CHARS characters (a log line stays readable)."""
    text = str(text)
    if len(text) <= limits.MAX_REASON_CHARS:
        return text
    return text[:limits.MAX_REASON_CHARS - 3] + '...'


def service_values(service, request):
    """Return {argument: value} of a request to dmp_server's ``service``; raise ValueError."""
    given = {}
    for argument in request.parameters:
        value = parameter_value_to_python(argument.value)
        if value is not None:
            given[argument.name] = plain(value)
    return DESCRIPTION.service(service).values(given)


class Teaching:
    """Learn taught demonstrations into ``library`` and save them to ``skills_dir``."""

    def __init__(self, library, skills_dir, logger, node_name, events):
        """
        Teach into ``library``; log with ``logger``; ``node_name`` names ~/teach.

        ``events``: the node's EventPublisher (a skill ``learned`` or ``refused``, as data).
        """
        self._library, self._skills_dir = library, skills_dir
        self._logger, self._node_name, self._events = logger, node_name, events

    def _protected_sources(self, name, settings):
        """Return the sources a taught skill ``name`` must not replace (teach_overwrite)."""
        source = self._library.source(name)
        if source is None or settings.teach_overwrite or source.startswith(TAUGHT):
            return ()
        skills_dir = pathlib.Path(self._skills_dir).expanduser()
        if source != 'built-in' and pathlib.Path(source).parent == skills_dir:
            return ()   # taught before and saved: re-teaching replaces it
        return (source,)

    def on_demonstration(self, data, settings):
        """Learn a Path on /etdmp/demonstrations as teach_skill_name (ros2 topic pub)."""
        try:
            if len(data) > limits.MAX_TAUGHT_PATH_BYTES:
                raise ValueError(f'the Path is {len(data)} bytes, more than '
                                 f'MAX_TAUGHT_PATH_BYTES = {limits.MAX_TAUGHT_PATH_BYTES} (about '
                                 f'{limits.MAX_DEMO_SAMPLES} poses, MAX_DEMO_SAMPLES); not '
                                 'decoded')
            frame, pose_frames, stamps, positions, quaternions = path_from_cdr(data)
            wrong = sorted(({frame} | pose_frames) - set(BASE_FRAMES))
            if wrong:
                raise ValueError(f'frame {short(repr(wrong[0]))} is not base_link (no TF here)')
            t = (stamps - stamps[0]) * 1e-9 if len(stamps) else None
            quaternions = recorded_orientations(quaternions)
        except ValueError as err:
            self._taught(settings.teach_skill_name, err)
            return
        self._teach(settings.teach_skill_name, t, positions, quaternions, settings,
                    '/etdmp/demonstrations')

    def on_teach(self, request, response, settings):
        """Serve ~/teach: the skill's name and its demonstration are in the request."""
        name = next((a.value.string_value for a in request.parameters if a.name == 'name'), '')
        try:
            given = service_values('teach', request)
            name = check_skill_name(given['name'])
            if len(given['t']) > limits.MAX_DEMO_SAMPLES:
                raise ValueError(f'{len(given["t"])} samples, more than MAX_DEMO_SAMPLES = '
                                 f'{limits.MAX_DEMO_SAMPLES}')
            t = np.asarray(given['t'], dtype=float)
            positions = np.asarray(given['positions'], dtype=float)
            quaternions = np.asarray(given.get('orientations', []), dtype=float)
            if positions.size != 3 * t.size or quaternions.size not in (0, 4 * t.size):
                raise ValueError(f'{t.size} times need {3 * t.size} position values (x, y, z '
                                 f'each) and none or {4 * t.size} orientation values, got '
                                 f'{positions.size} and {quaternions.size}')
            positions = positions.reshape(-1, 3)
            quaternions = recorded_orientations(quaternions.reshape(-1, 4)) \
                if quaternions.size else None
            if 'recorded_dim' in given:
                settings = replace(settings, recorded_dim=given['recorded_dim'])
        except ValueError as err:
            response.result.reason = self._taught(name, err)
            return response
        response.result.successful, response.result.reason = self._teach(
            name, t - t[0] if t.size else t, positions, quaternions, settings,
            f'/{self._node_name}/teach')
        return response

    def _teach(self, name, t, positions, quaternions, settings, where):
        """
        Learn a demonstration as skill ``name`` and save it; return (learned, what was done).

        What happened is logged too (INFO, or ERROR with the reason); a refused demonstration
        replaces nothing.
        """
        try:
            if len(positions) > limits.MAX_DEMO_SAMPLES:
                raise ValueError(f'{len(positions)} poses, more than MAX_DEMO_SAMPLES = '
                                 f'{limits.MAX_DEMO_SAMPLES}')
            if len(positions):
                bounded(positions[np.argmax(np.abs(positions).max(axis=1))], 'a pose')
            with np.errstate(over='raise', invalid='raise', divide='raise'):
                demo = recorded_path_demo(name, positions, t, settings.plane,
                                          settings.recorded_dim, settings.plane_tolerance,
                                          quaternions)
                check_usable(demo, settings.plan)
                entry = self._library.add(name, demo, TAUGHT + where,
                                          protected=self._protected_sources(name, settings))
        except (ValueError, ArithmeticError) as err:
            return False, self._taught(name, err)
        log = self._logger
        try:
            file, save_error = str(save_skill_demo(self._skills_dir, entry.demo)), ''
            saved = f'saved to {file}'
        except (OSError, ValueError) as err:
            saved = f'NOT saved (it is lost on restart): {err}'
            file, save_error = '', str(err)
            log.error(f'taught skill {name!r} {saved}')
        text = (f'learned skill {name!r} ({demo.dim}D, {demo.n_samples} samples) from {where}, '
                f'{saved}')
        log.info(text)
        self._events.publish('learned', text, skill=name, dim=demo.dim, samples=demo.n_samples,
                             duration_s=demo.duration, source=where, saved=file,
                             save_error=save_error)
        return True, text

    def _taught(self, name, err):
        """Log (ERROR) and return why a taught demonstration of skill ``name`` is refused."""
        hint = ''
        if 'exists already' in str(err):
            hint = ' (set teach_overwrite to true to replace it, or choose another name)'
        text = (f'taught demonstration for skill {name!r} rejected: {short(err)}{hint}; the '
                'skills already learned are kept')
        self._logger.error(text)
        self._events.publish('refused', text, ERROR, skill=name, reason=f'{short(err)}{hint}')
        return text
