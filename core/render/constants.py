"""Constants of the Gaussian splatting image model, shared by every rasterizer backend.

- Gaussians with camera z <= ``NEAR_PLANE`` (metres) are culled.
- The 2D covariance gets ``LOW_PASS`` px^2 added on its diagonal (3DGS's dilation, smaller than
  its 0.3: that minimum footprint spilled ~20 % alpha one pixel across depth edges and
  silhouettes, which dominated the held-out depth error on the benchmark).
- The numba kernels freeze these constants when compiled; their on-disk cache is keyed on the
  values (core/render/cpu/jit.py), so a change here compiles them afresh.
- The Jacobian of the projection is evaluated with x/z, y/z clamped to ``FOV_PAD`` beyond the
  image edges (as a fraction of the half field of view), as gsplat does.
- A Gaussian touches a pixel centre only inside its ``SIGMA_CUTOFF`` sigma ellipse, i.e.
  where ``power = 0.5 d^T conic d <= POWER_CUTOFF``.
- ``alpha = min(ALPHA_MAX, opacity * exp(-power))``; pairs with ``alpha < ALPHA_MIN`` are
  skipped; compositing stops before the first Gaussian that would bring the transmittance
  below ``T_MIN``.
- Depth is planar per Gaussian: at pixel p it contributes the depth of its max-density point
  along p's ray, linearised about its projected mean m: ``z + a . (p - m)``. With the camera-frame
  mean t (z = t_z) and covariance Sigma, ``a = -z^2 (Sigma^-1 t)_{x,y} / (t^T Sigma^-1 t (fx, fy))``
  (the ray-intersection depth ``r^T Sigma^-1 t / r^T Sigma^-1 r``, r = ((u-cx)/fx, (v-cy)/fy, 1),
  differentiated at r = t / z); each component of ``a`` is limited to ``MAX_SLOPE`` pixel
  footprints (z / f) per pixel (a disc seen edge-on). A flat disc thus renders its plane's depth.
"""

NEAR_PLANE = 0.01
LOW_PASS = 0.1
FOV_PAD = 0.3
SIGMA_CUTOFF = 3.0
POWER_CUTOFF = 0.5 * SIGMA_CUTOFF ** 2
ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4
MAX_SLOPE = 3.0
