"""Build script for the etdmp_ros ament_python package (pip, colcon and ROS 2 alike)."""

from glob import glob
import os

from setuptools import find_packages
from setuptools import setup

package_name = 'etdmp_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    # The built-in demonstrations ship inside the Python package and are read with
    # importlib.resources, so they work from a source tree, a venv and a colcon install.
    package_data={'etdmp_ros.dmp': ['data/*.csv'],
                  # The teaching page (etdmp_ros/nodes/teach.py serves it); py.typed: the
                  # package's annotations serve type checkers of code that uses it (PEP 561).
                  'etdmp_ros': ['teach_page/*.html', 'teach_page/*.js', 'teach_page/*.css',
                                'py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        (os.path.join('share', package_name), ['package.xml']),
        (os.path.join('share', package_name, 'config'),
         sorted(glob('config/*.yaml') + glob('config/*.xml'))),
        (os.path.join('share', package_name, 'launch'), sorted(glob('launch/*.py'))),
    ],
    install_requires=['setuptools'],
    extras_require={
        'plot': ['matplotlib'],
        'test': ['pytest'],
    },
    zip_safe=True,
    maintainer='etdmp_ros maintainers',
    maintainer_email='maintainers@example.com',
    description='Euclidean-transformation DMPs (ET-DMPs) on a simulated UR10 with ROS 2.',
    license='Apache-2.0',
    python_requires='>=3.11',
    entry_points={
        'console_scripts': [
            # Offline command line (no ROS needed): generalize, reproduce the paper, plot.
            'etdmp = etdmp_ros.apps.cli:main',
            # ROS 2 nodes: `ros2 run etdmp_ros <node>` (setup.cfg puts scripts in lib/etdmp_ros).
            'ur10_sim = etdmp_ros.nodes.ur10_sim:main',
            'dmp_server = etdmp_ros.nodes.dmp_server:main',
            'controller = etdmp_ros.nodes.controller:main',
            'bringup = etdmp_ros.nodes.bringup:main',
            'perception = etdmp_ros.nodes.perception:main',
            'teach = etdmp_ros.nodes.teach:main',
        ],
    },
)
