"""strahl.render: the renderer from Python, checked on scenes whose pixels are known."""

from pathlib import Path

import numpy as np
import pytest

import strahl

DATA = Path(__file__).resolve().parents[2] / "data"

# A 4 × 4 quad facing the camera that fills its view, lit by ambient light only: every pixel
# is ambient · kd · the scene's ambient, and a view past it shows the background.
AMBIENT_QUAD = """
[camera]
eye = [0.0, 0.0, -3.0]
look_at = [0.0, 0.0, 0.0]
fov = 40.0

[render]
width = 24
height = 16
background = [0.1, 0.2, 0.3]
ambient = [1.0, 0.5, 0.25]

[material.grey]
color = [0.8, 0.6, 0.4]
ambient = 0.5

[mesh.wall]
quad = { size = [4.0, 4.0] }
material = "grey"

[[instance]]
mesh = "wall"
rotate = [-90.0, 0.0, 0.0]
"""


def test_known_pixels(tmp_path):
    f = tmp_path / "quad.toml"
    f.write_text(AMBIENT_QUAD)
    r = strahl.render(f, threads=1)
    assert r.image.shape == (16, 24, 3) and r.image.dtype == np.float32
    assert r.srgb.shape == (16, 24, 3) and r.srgb.dtype == np.uint8
    want = np.float32([0.8, 0.6, 0.4]) * 0.5 * np.float32([1.0, 0.5, 0.25])
    np.testing.assert_allclose(r.image.reshape(-1, 3), np.tile(want, (24 * 16, 1)), rtol=1e-6)
    srgb = np.where(want <= 0.0031308, 12.92 * want, 1.055 * want ** (1 / 2.4) - 0.055)
    np.testing.assert_array_equal(r.srgb[0, 0], (srgb * 255 + 0.5).astype(np.uint8))
    assert r.stats["rays"] == {"primary": 24 * 16, "shadow": 0, "reflected": 0, "refracted": 0}
    assert (r.stats["width"], r.stats["height"], r.stats["spp"]) == (24, 16, 1)
    # Looking away from the quad: the background everywhere.
    f.write_text(AMBIENT_QUAD.replace("eye = [0.0, 0.0, -3.0]", "eye = [0.0, 0.0, -3.0]\nup = [0.0, 1.0, 0.0]")
                 .replace("look_at = [0.0, 0.0, 0.0]", "look_at = [0.0, 0.0, -6.0]"))
    away = strahl.render(f, width=5, height=3)
    np.testing.assert_allclose(away.image.reshape(-1, 3), np.tile([0.1, 0.2, 0.3], (15, 1)), rtol=1e-6)


def test_data_scene_is_the_same_for_any_thread_count():
    a = strahl.render(DATA / "whitted.toml", width=64, height=48, threads=1)
    b = strahl.render(DATA / "whitted.toml", width=64, height=48, threads=2)
    assert a.image.shape == (48, 64, 3)
    np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.srgb, b.srgb)
    assert np.isfinite(a.image).all() and (a.image >= 0).all()
    assert a.image.std() > 0.05, "a chequerboard, two balls and the sky are not one colour"
    rays = a.stats["rays"]
    assert rays["primary"] == 64 * 48 and rays["shadow"] > 0 and rays["reflected"] > 0 and rays["refracted"] > 0
    assert b.stats["threads"] == 2 and 0 < b.stats["query_share"] <= 1
    # More samples per pixel: each pixel averages its jittered samples.
    c = strahl.render(DATA / "whitted.toml", width=64, height=48, spp=4, max_depth=2)
    assert c.stats["rays"]["primary"] == 4 * 64 * 48 and c.stats["max_depth"] == 2
    assert np.abs(c.image - a.image).mean() < 0.1


def test_bad_render_input(tmp_path):
    with pytest.raises(OSError):
        strahl.render(tmp_path / "missing.toml")
    f = tmp_path / "quad.toml"
    f.write_text(AMBIENT_QUAD)
    for kw, match in [({"spp": 0}, "samples"), ({"width": 0}, "size"), ({"height": 40000}, "size"),
                      ({"max_depth": 65}, "depth"), ({"bailout": 2.0}, "bailout"), ({"bailout": float("nan")}, "bailout"),
                      ({"width": -1}, "width"), ({"spp": 1.5}, "spp"), ({"threads": -1}, "threads")]:
        with pytest.raises(ValueError, match=match):
            strahl.render(f, **kw)
    no_camera = tmp_path / "no_camera.toml"
    no_camera.write_text("[render]" + AMBIENT_QUAD.split("[render]")[1])
    with pytest.raises(ValueError, match="has no \\[camera\\]"):
        strahl.render(no_camera)
    bad = tmp_path / "bad.toml"
    bad.write_text(AMBIENT_QUAD.replace('material = "grey"', 'material = "nope"'))
    with pytest.raises(ValueError, match="nope"):
        strahl.render(bad)


def test_ray_tree_matches_the_rendered_pixel():
    scene = DATA / "whitted.toml"
    img = strahl.render(scene, width=64, height=48).image
    # A pixel on the glass ball (refracted rays) and one on the floor only.
    for x, y in [(40, 22), (5, 45)]:
        nodes, colour = strahl.ray_tree(scene, x, y, width=64, height=48)
        np.testing.assert_allclose(colour, img[y, x], rtol=1e-5, atol=1e-6)
        assert nodes[0]["kind"] == "primary" and nodes[0]["parent"] is None and nodes[0]["depth"] == 0
        for i, n in enumerate(nodes[1:], 1):
            p = nodes[n["parent"]]
            assert n["parent"] < i, "parents come first"
            assert n["depth"] == p["depth"] + (n["kind"] != "shadow")
            assert p["t"] is not None, "only a ray that hit spawns rays"
            np.testing.assert_allclose(n["origin"], np.add(p["origin"], np.multiply(p["dir"], p["t"])), atol=1e-3)
        kinds = {n["kind"] for n in nodes}
        assert "shadow" in kinds
        if (x, y) == (40, 22):
            assert "refracted" in kinds, kinds
        else:
            assert kinds <= {"primary", "shadow"} or "reflected" in kinds
    with pytest.raises(ValueError, match="outside"):
        strahl.ray_tree(scene, 64, 0, width=64, height=48)
    with pytest.raises(ValueError, match="x"):
        strahl.ray_tree(scene, -1, 0)
