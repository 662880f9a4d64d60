"""Blender reads the OpenEXR images Madder writes: every compression Madder's own encoder
makes (RLE, the default, and none), as half floats, with the rows where `Image.pixels`
has them (row 0 at the bottom), so a texture baked by `rasterize` + `write_exr` is the
image Blender shows."""

import bpy
import numpy as np

import madder


def test_blender_reads_madder_exr_images_as_written(tmp_path):
    rng = np.random.default_rng(1)
    h, w = 64, 96
    img = np.zeros((h, w, 4), np.float32)  # mostly empty, as a stain frame is
    img[10:30, 20:70] = rng.random((20, 50, 4), dtype=np.float32)
    img[40:50, :, 0] = 0.5
    img[..., 3] = np.linspace(0.0, 1.0, w, dtype=np.float32)[None, :]
    img[5, 7] = (1e-5, 300.0, -2.0, 0.0)  # a subnormal half, a large value, a negative one
    path = tmp_path / "stain.exr"
    madder.write_exr(path, img)
    image = bpy.data.images.load(str(path))
    try:
        assert tuple(image.size) == (w, h) and image.channels == 4 and image.is_float
        pixels = np.empty(w * h * 4, np.float32)
        image.pixels.foreach_get(pixels)
        assert np.array_equal(pixels.reshape(h, w, 4), img.astype(np.float16).astype(np.float32))
    finally:
        bpy.data.images.remove(image)
