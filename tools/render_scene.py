#!/usr/bin/env python3
"""
Render the simulated camera's view of the workcell for the README (and to aim the camera).

Writes ``docs/img/camera_frame.png`` (the rgb8 image ur10_sim publishes) and
``docs/img/camera_depth.png`` (the aligned 16UC1 depth, colour-mapped near = warm, no data =
black), with the robot at ``initial_joint_positions`` and the scene of ``config/scene.yaml``.
Usage (MUJOCO_GL=egl renders headless)::

    MUJOCO_GL=egl .venv/bin/python tools/render_scene.py [--out docs/img]
    MUJOCO_GL=egl .venv/bin/python tools/render_scene.py --look-at 1.55 0.05 0.85 0.72 0.05 0.0

``--look-at EYE TARGET`` aims the camera from EYE at TARGET (base_link, image top towards +z)
and prints the ``camera.orientation`` quaternion to put into config/scene.yaml.
"""

import argparse
import os
from pathlib import Path

import cv2
from etdmp_ros.geometry.camera import CameraPose
from etdmp_ros.ros import system
from etdmp_ros.sim import UR10Sim
import numpy as np

REPO = Path(__file__).resolve().parents[1]


def depth_picture(depth_mm):
    """Return a BGR picture of a depth image: turbo colour map, 0 (no data) black."""
    valid = depth_mm > 0
    near, far = np.percentile(depth_mm[valid], [1, 99]) if valid.any() else (0, 1)
    scaled = np.clip((far - depth_mm.astype(float)) / max(far - near, 1.0), 0, 1)
    picture = cv2.applyColorMap((scaled * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    picture[~valid] = 0
    return picture


def main():
    """Render and write the pictures."""
    os.environ.setdefault('MUJOCO_GL', 'egl')
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--out', type=Path, default=REPO / 'docs' / 'img')
    parser.add_argument('--look-at', type=float, nargs=6, metavar=('EX', 'EY', 'EZ', 'TX', 'TY',
                                                                   'TZ'))
    args = parser.parse_args()
    overrides = {}
    if args.look_at:
        pose = CameraPose.look_at(args.look_at[:3], args.look_at[3:])
        overrides = {'camera.position': list(pose.position),
                     'camera.orientation': list(pose.orientation)}
        print('camera:\n  position: [%s]\n  orientation: [%s]' % (
            ', '.join(f'{v:.6g}' for v in pose.position),
            ', '.join(f'{v:.6f}' for v in pose.orientation)))
    with UR10Sim(system.scene_config(overrides)) as sim:
        rgb, depth_mm = sim.render_rgb_depth()
        k = sim.intrinsics
    args.out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out / 'camera_frame.png'), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(args.out / 'camera_depth.png'), depth_picture(depth_mm))
    print(f'wrote {args.out}/camera_frame.png and camera_depth.png: {k.width}x{k.height}, '
          f'f = {k.fx:.1f} px, depth {depth_mm[depth_mm > 0].min()}..{depth_mm.max()} mm')


if __name__ == '__main__':
    main()
