"""The simulated camera: one offscreen MuJoCo render pass giving colour and depth."""

from __future__ import annotations

from typing import Any

from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.sim._workcell import import_mujoco, VISIBLE_GROUP
import numpy as np
from numpy.typing import NDArray


class OffscreenCamera:
    """One offscreen render pass reading colour AND depth (mujoco.Renderer needs two)."""

    def __init__(self, model: Any, camera_id: int, intrinsics: CameraIntrinsics) -> None:
        """Create the OpenGL context (current in this thread) and the buffers."""
        mujoco = import_mujoco()
        self.model = model
        w, h = intrinsics.width, intrinsics.height
        self._gl = mujoco.GLContext(w, h)
        self._gl.make_current()
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        # Reversed z (1 at near, 0 at far) with a float depth buffer: precise at any distance.
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=1000)
        self._option = mujoco.MjvOption()
        self._option.geomgroup[:] = 0
        self._option.geomgroup[VISIBLE_GROUP] = 1
        self._option.sitegroup[:] = 0
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = camera_id
        self._rect = mujoco.MjrRect(0, 0, w, h)
        self._rgb = np.empty((h, w, 3), dtype=np.uint8)
        self._depth = np.empty((h, w), dtype=np.float32)
        near = model.vis.map.znear * model.stat.extent
        far = model.vis.map.zfar * model.stat.extent
        # OpenGL projection z_ndc = (c z + d) / -z (glFrustum), remapped to reversed z in
        # [0, 1]: window depth = (c' z + d') / -z, so the distance -z = d' / (depth + c').
        c = -(far + near) / (far - near)
        d = -2.0 * far * near / (far - near)
        self._c = np.float32(-0.5 * c - 0.5)
        self._d = np.float32(-0.5 * d)

    def render(self, data: Any) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
        """Return rgb uint8 (H, W, 3) and depth float32 metres (H, W) (inf where nothing)."""
        mujoco = import_mujoco()
        self._gl.make_current()
        mujoco.mjv_updateScene(self.model, data, self._option, None, self._camera,
                               mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        mujoco.mjr_render(self._rect, self._scene, self._context)
        mujoco.mjr_readPixels(self._rgb, self._depth, self._rect, self._context)
        # OpenGL rows start at the bottom of the image.
        rgb = self._rgb[::-1].copy()
        with np.errstate(divide='ignore'):
            depth = self._d / (self._depth[::-1] + self._c)
        return rgb, depth

    def close(self) -> None:
        """Free the OpenGL context."""
        if self._gl is not None:
            self._gl.make_current()
            self._context.free()
            self._gl.free()
            self._gl = None

    def __del__(self) -> None:
        """Free the OpenGL context if still held."""
        try:
            self.close()
        except Exception:   # noqa: B902 - interpreter shutdown: nothing left to free
            pass
