"""Segment an Open3D RGB-D frame's depth into planes with rangeseg and draw them (not run in CI).

    pip install . open3d
    python examples/python/open3d_planes.py [DEPTH.png COLOR.jpg]

Without arguments it uses Open3D's own sample frame (SampleRedwoodRGBDImages). Each plane's pixels are
back-projected with the camera and painted one colour; the plane normals are drawn as short line segments
from the centroids.
"""

from __future__ import annotations

import sys

import numpy as np
import open3d as o3d

import rangeseg


def main() -> None:
    if len(sys.argv) == 3:
        depth_path, color_path = sys.argv[1:]
    else:
        sample = o3d.data.SampleRedwoodRGBDImages()
        depth_path, color_path = sample.depth_paths[0], sample.color_paths[0]
    intr = o3d.camera.PinholeCameraIntrinsic(o3d.camera.PinholeCameraIntrinsicParameters.PrimeSenseDefault)
    fx, fy = intr.get_focal_length()
    cx, cy = intr.get_principal_point()

    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.io.read_image(color_path), o3d.io.read_image(depth_path), depth_scale=1000.0, depth_trunc=4.0,
        convert_rgb_to_intensity=False,
    )
    depth = np.asarray(rgbd.depth)  # float32 metres, 0 = no data
    camera = rangeseg.Pinhole(fx, fy, cx, cy)
    result = rangeseg.segment(depth, camera)
    big = result.planes[result.planes["pixels"] >= 2000]
    print(f"{len(result.planes)} regions, {len(big)} with at least 2000 pixels; timings {result.timings}")
    for p in big:
        n, d = p["normal"], p["d"]
        print(f"  label {p['label']:3d}: {n[0]:+.3f} x {n[1]:+.3f} y {n[2]:+.3f} z = {d:+.3f} m"
              f"  ({p['pixels']} px, rms {1000 * p['rms']:.1f} mm)")

    # Back-project every labelled pixel and colour it by its plane.
    v, u = np.nonzero(np.isin(result.labels, big["label"]))
    z = depth[v, u].astype(np.float64)
    xyz = np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=1)
    rng = np.random.default_rng(0)
    palette = {int(l): rng.uniform(0.2, 1.0, 3) for l in big["label"]}
    colors = np.array([palette[int(l)] for l in result.labels[v, u]])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    cloud.colors = o3d.utility.Vector3dVector(colors)

    # Normals: a 0.2 m segment from each centroid along the plane's normal (toward the camera).
    starts = big["centroid"]
    ends = starts + 0.2 * big["normal"]
    lines = o3d.geometry.LineSet(
        o3d.utility.Vector3dVector(np.vstack([starts, ends])),
        o3d.utility.Vector2iVector([[i, i + len(big)] for i in range(len(big))]),
    )
    # The rest of the frame in its own colours, for context.
    scene = o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, intr)
    o3d.visualization.draw_geometries([scene, cloud, lines], window_name="rangeseg planes")


if __name__ == "__main__":
    main()
