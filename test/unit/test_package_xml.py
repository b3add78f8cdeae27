"""
package.xml lists exactly what the package's code imports, by rosdep key, and nothing unused.

Every top-level module that ``etdmp_ros/`` and ``launch/`` import (anywhere: conditional and
optional imports such as tf2_msgs count) that is not the standard library's is an
``exec_depend``: a ROS package by its own name, a Python library by the rosdep key of
:data:`PYTHON_KEYS`. :data:`NOT_IMPORTED` holds the one dependency used without an import.
"""

import ast
from pathlib import Path
import sys
from xml.etree import ElementTree

REPO = Path(__file__).resolve().parents[2]
CODE = ('etdmp_ros', 'launch')
#: Python libraries that are not ROS packages: import name -> rosdep key.
PYTHON_KEYS = {
    'aiohttp': 'python3-aiohttp',
    'cv2': 'python3-opencv',
    'matplotlib': 'python3-matplotlib',
    'mcap': 'python3-mcap-pip',
    'mcap_ros2': 'python3-mcap-ros2-support-pip',
    'mujoco': 'python3-mujoco-pip',
    'numba': 'python3-numba',
    'numpy': 'python3-numpy',
    'PIL': 'python3-pil',
    'pinocchio': 'pinocchio',
    'yaml': 'python3-yaml',
}
#: Dependencies that no import shows: key -> why.
NOT_IMPORTED = {'example-robot-data': 'the UR10 URDF and meshes (robot/_ur10.py finds them)'}


def imported_modules():
    """Return {top-level module: [files importing it]} of the package's code, stdlib excluded."""
    found = {}
    for folder in CODE:
        for path in sorted((REPO / folder).rglob('*.py')):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    top = name.split('.')[0]
                    if top not in sys.stdlib_module_names and top != 'etdmp_ros':
                        found.setdefault(top, []).append(str(path.relative_to(REPO)))
    return found


def package_xml(tag):
    """Return the texts of ``tag`` elements of package.xml."""
    root = ElementTree.parse(REPO / 'package.xml').getroot()
    return [e.text.strip() for e in root.iter(tag)]


def test_exec_depends_are_exactly_the_imports():
    modules = imported_modules()
    needed = {PYTHON_KEYS.get(m, m): files for m, files in modules.items()}
    needed.update({key: [why] for key, why in NOT_IMPORTED.items()})
    listed = package_xml('exec_depend')
    assert len(listed) == len(set(listed)), f'listed twice: {listed}'
    missing = {key: needed[key][:3] for key in sorted(set(needed) - set(listed))}
    unused = sorted(set(listed) - set(needed))
    assert not missing, f'imported but not in package.xml (key: importing files): {missing}'
    assert not unused, f'in package.xml but not imported: {unused}'


def test_the_scan_sees_conditional_imports():
    # tf2_msgs is imported only inside functions, and only when installed; pinocchio at the top.
    modules = imported_modules()
    assert 'etdmp_ros/ros/conversions/_tf.py' in modules['tf2_msgs']
    assert 'etdmp_ros/robot/_ur10.py' in modules['pinocchio']
    assert 'os' not in modules and 'etdmp_ros' not in modules
    assert set(PYTHON_KEYS) <= set(modules), 'PYTHON_KEYS has modules nothing imports'
