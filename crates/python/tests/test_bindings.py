"""Every binding against the mdtf command on the same phantom (bit for
bit), and the readers and writers against nibabel."""

from __future__ import annotations

import json
import re
from pathlib import Path

import nibabel
import nrrd
import numpy as np
import pytest

import mdtf
from conftest import cli


def zyx(path: Path) -> np.ndarray:
    """A NIfTI file's samples as (z, y, x) or (component, z, y, x), read by nibabel."""
    data = np.asarray(nibabel.load(path).dataobj, dtype=np.float32)
    return data.T if data.ndim == 3 else data.transpose(3, 2, 1, 0)


def test_read_gives_nibabels_samples_and_affine(sphere: Path) -> None:
    vol = mdtf.read(sphere)
    img = nibabel.load(sphere)
    np.testing.assert_array_equal(vol.data, np.asarray(img.dataobj, dtype=np.float32).T)
    np.testing.assert_allclose(np.array(vol.world_from_voxel), img.affine, atol=1e-5)
    assert vol.spacing == pytest.approx((1.2, 1.0, 0.8))
    assert vol.data.shape == (48, 44, 40) and vol.data.dtype == np.float32


def test_write_is_read_by_nibabel_with_the_grid(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    data = rng.normal(size=(5, 6, 7)).astype(np.float32)
    out = tmp_path / "w.nii.gz"
    mdtf.write(out, data, spacing=(3.0, 2.0, 0.5), origin={"z": -1.0, "y": 4.0, "x": 10.0})
    img = nibabel.load(out)
    np.testing.assert_array_equal(np.asarray(img.dataobj, dtype=np.float32).T, data)
    assert img.header.get_zooms() == pytest.approx((0.5, 2.0, 3.0))
    assert img.affine[:3, 3] == pytest.approx((10.0, 4.0, -1.0))
    # and a Volume goes back out with its own orientation
    rotated = nibabel.Nifti1Image(data.T, np.array([[0, -2.0, 0, 5], [0.5, 0, 0, 6], [0, 0, 3.0, 7], [0, 0, 0, 1]]))
    src = tmp_path / "rot.nii"
    nibabel.save(rotated, src)
    again = tmp_path / "again.nii"
    mdtf.write(again, mdtf.read(src))
    np.testing.assert_allclose(nibabel.load(again).affine, rotated.affine, atol=1e-6)


def test_write_never_replaces_a_folder_it_did_not_write(tmp_path: Path) -> None:
    keep = tmp_path / "mine.ome.zarr"
    keep.mkdir()
    (keep / "notes.txt").write_text("precious")
    with pytest.raises(mdtf.MdtfError):
        mdtf.write(keep, np.zeros((4, 4, 4), np.float32))
    assert (keep / "notes.txt").read_text() == "precious"


def test_derive_equals_the_command(mdtf_bin: Path, sphere: Path, tmp_path: Path) -> None:
    cli(mdtf_bin, "derive", sphere, "--items", "g,f2,normal,laplacian", "--kernel", "bspline3", "-o", tmp_path / "d")
    vol = mdtf.read(sphere)
    got = mdtf.derive(vol.data, vol.spacing, items=["g", "f2", "normal", "laplacian"], kernel="bspline3")
    for item in ["g", "f2", "laplacian"]:
        np.testing.assert_array_equal(got[item], zyx(tmp_path / "d" / f"{item}.nii.gz"), err_msg=item)
    normal = zyx(tmp_path / "d" / "normal.nii.gz")
    for k, c in enumerate(["nx", "ny", "nz"]):
        np.testing.assert_array_equal(got[c], normal[k], err_msg=c)


def test_derive_of_several_fields_equals_the_command(mdtf_bin: Path, tmp_path: Path) -> None:
    src = tmp_path / "mf.nrrd"
    cli(mdtf_bin, "synth", "multifield", "--size", "24", "-o", src)
    cli(mdtf_bin, "derive", src, "--items", "gnorm", "-o", tmp_path / "d")
    vol = mdtf.read(src)
    assert len(vol.fields) == 3
    got = mdtf.derive(vol.fields, vol.spacing, items=["gnorm"])
    np.testing.assert_array_equal(got["gnorm"], zyx(tmp_path / "d" / "gnorm.nii.gz"))


def test_bilateral_equals_the_command(mdtf_bin: Path, sphere: Path, tmp_path: Path) -> None:
    cli(mdtf_bin, "bilateral", sphere, "--sigma-d", "1.5", "--sigma-r", "0.1", "-o", tmp_path / "f.nii")
    vol = mdtf.read(sphere)
    got = mdtf.bilateral(vol.data, vol.spacing, sigma_d=1.5, sigma_r=0.1)
    np.testing.assert_array_equal(got, zyx(tmp_path / "f.nii"))


def test_boundary_equals_the_command(mdtf_bin: Path, sphere: Path, tmp_path: Path) -> None:
    cli(mdtf_bin, "boundary", sphere, "--kernel", "gauss:1", "--d-max", "9", "-o", tmp_path / "b")
    vol = mdtf.read(sphere)
    got = mdtf.boundary(vol.data, vol.spacing, kernel="gauss:1", d_max=9.0)
    for name in ["distance", "g_hit", "hit", "dot"]:
        np.testing.assert_array_equal(getattr(got, name), zyx(tmp_path / "b" / f"{name}.nii.gz"), err_msg=name)
    s = got.summary
    assert s["d_max"] == 9.0
    assert s["hits"] == int((got.hit == 1).sum()) and s["hits"] > 1000
    assert s["hits"] + s["not_traced"] + s["no_crossing"] + s["rejected"] == got.hit.size


def test_histogram_equals_the_command(mdtf_bin: Path, sphere: Path, tmp_path: Path) -> None:
    cli(mdtf_bin, "histogram", sphere, "--axes", "v,g", "--bins", "64,32", "-o", tmp_path / "h")
    vol = mdtf.read(sphere)
    g = mdtf.derive(vol.data, vol.spacing, items=["g"])["g"]
    got = mdtf.histogram({"v": vol.data, "g": g}, bins={"v": 64, "g": 32})
    counts, _ = nrrd.read(str(tmp_path / "h" / "hist_v_g.nrrd"), index_order="C")
    np.testing.assert_array_equal(got.counts, counts)
    # counts are 64-bit in memory; the file stays uint32 while every count fits
    assert got.counts.dtype == np.uint64 and counts.dtype == np.uint32
    meta = json.loads((tmp_path / "h" / "hist_v_g.json").read_text())
    for (name, lo, hi, bins), axis in zip(got.axes, meta["axes"]):
        assert (name, lo, hi, bins) == (axis["name"], axis["min"], axis["max"], axis["bins"])
    # and against a brute-force count of the documented bin rule, floor((x - min) bins / (max - min)),
    # the maximum in the last bin, voxels outside either range (g's is clipped) left out
    def bins_of(x: np.ndarray, axis: tuple[str, float, float, int]) -> tuple[np.ndarray, np.ndarray]:
        _, lo, hi, n = axis
        x = x.astype(np.float64).ravel()
        return np.minimum(np.floor((x - lo) * (n / (hi - lo))), n - 1).astype(int), (x >= lo) & (x <= hi)

    (bv, inv), (bg, ing) = bins_of(vol.data, got.axes[0]), bins_of(g, got.axes[1])
    inside = inv & ing
    assert inside.sum() < inside.size, "g's range is clipped"
    ref = np.zeros((32, 64), np.int64)
    np.add.at(ref, (bg[inside], bv[inside]), 1)
    np.testing.assert_array_equal(got.counts, ref)


def test_histogram_with_a_mask_counts_only_its_voxels(sphere: Path) -> None:
    v = mdtf.read(sphere).data
    mask = v > np.median(v)
    got = mdtf.histogram({"v": v}, ranges={"v": (float(v.min()), float(v.max()) + 1)}, bins=10, mask=mask)
    assert got.counts.sum() == mask.sum()


def test_quantise_codes_decode_to_within_half_a_step(sphere: Path) -> None:
    v = mdtf.read(sphere).data
    lo, hi = float(v.min()), float(v.max())
    for dtype, top in [("u8", 255), ("u16", 65535)]:
        codes, offset, scale = mdtf.quantise(v, lo, hi, dtype)
        assert codes.dtype == np.dtype(dtype.replace("u", "uint")) and codes.min() == 0 and codes.max() == top
        assert scale == pytest.approx((hi - lo) / top) and offset == pytest.approx(lo)
        assert np.abs(offset + scale * codes.astype(np.float64) - v).max() <= scale / 2 * (1 + 1e-9)
    # signed: 0 is exactly a code
    codes, offset, scale = mdtf.quantise(v - 50, lo - 50, hi - 50, "u8", signed=True)
    z = -offset / scale
    assert z == pytest.approx(round(z), abs=1e-9)
    half, _, _ = mdtf.quantise(v, lo, hi, "f16")
    np.testing.assert_array_equal(half, v.astype(np.float16))


def test_run_equals_the_command(mdtf_bin: Path, pipelines: Path, tmp_path: Path) -> None:
    pipeline = pipelines / "distance-tf.toml"
    cli(mdtf_bin, "run", pipeline, "--set", "input.size=32", "--set", "preview=false", "-o", tmp_path / "cli")
    report = mdtf.run(pipeline, tmp_path / "py", input__size=32, preview=False)
    assert report["dims"] == [32, 32, 32] and report["settings"]["input"]["size"] == 32
    for f in sorted((tmp_path / "cli" / "pack").iterdir()):
        if f.name != "manifest.json":
            assert (tmp_path / "py" / "pack" / f.name).read_bytes() == f.read_bytes(), f.name
    # the pack's g_hit and distance codes are mdtf.quantise of the kept volumes over the manifest's ranges
    manifest = json.loads((tmp_path / "cli" / "pack" / "manifest.json").read_text())
    for name in ["g_hit", "distance"]:
        entry = next(c for c in manifest["channels"] if c["name"] == name)
        texture = next(t for t in manifest["textures"] if t["name"] == entry["texture"])
        nx, ny, nz = texture["dims"]
        stored = np.dtype(texture["dtype"].replace("u", "uint"))
        raw = np.fromfile(tmp_path / "cli" / "pack" / texture["data"], dtype=stored)
        packed = raw.reshape(nz, ny, nx, texture["components"])[..., entry["component"]]
        kept = mdtf.read(tmp_path / "cli" / "volumes" / f"{name}.nii.gz").data
        codes, offset, scale = mdtf.quantise(kept, *entry["range"], texture["dtype"])
        assert (offset, scale) == pytest.approx((entry["decode"]["offset"], entry["decode"]["scale"]), rel=1e-12)
        np.testing.assert_array_equal(codes, packed, err_msg=name)
        assert len(np.unique(codes)) > (1 if name == "g_hit" else 20), name
    # slab by slab: the same textures
    mdtf.run(pipeline, tmp_path / "slabs", settings={"input.size": 32, "preview": False}, slab_planes=5)
    for f in sorted((tmp_path / "cli" / "pack").glob("*.raw")):
        assert (tmp_path / "slabs" / "pack" / f.name).read_bytes() == f.read_bytes(), f.name


def test_halo_and_plan_equal_the_command(mdtf_bin: Path, pipelines: Path) -> None:
    for name in ["distance-tf", "slicer-3dtf"]:
        pipeline = pipelines / f"{name}.toml"
        text = cli(mdtf_bin, "run", pipeline, "--plan", "--set", "input.size=40").stdout
        x, y, z = map(int, re.search(r"halo of a block: x (\d+), y (\d+), z (\d+)", text).groups())
        assert mdtf.halo(pipeline, input__size=40) == (z, y, x)
        # the command's first line names the pipeline file and input; the plan follows
        assert mdtf.plan(pipeline, input__size=40).strip() == text.split("\n", 1)[1].strip()


def test_a_missing_file_is_both_an_mdtf_error_and_a_file_not_found_error(tmp_path: Path, pipelines: Path) -> None:
    import errno

    missing = tmp_path / "nope.nii"
    for call in (
        lambda: mdtf.read(missing),
        lambda: mdtf.run(pipelines / "slicer-3dtf.toml", tmp_path / "out", input=missing),
        lambda: mdtf.plan(tmp_path / "nope.toml"),
    ):
        with pytest.raises(FileNotFoundError) as caught:
            call()
        assert isinstance(caught.value, mdtf.MdtfError)
        assert caught.value.errno == errno.ENOENT
        assert caught.value.filename in (str(missing), str(tmp_path / "nope.toml"))
    assert not (tmp_path / "out").exists()


def test_arrays_mdtf_cannot_take_as_they_are_are_value_errors_that_say_why(tmp_path: Path) -> None:
    real = np.zeros((4, 5, 6))
    # complex: the imaginary part is not dropped without a word
    with pytest.raises(ValueError, match=r"complex values \(complex128\).*\.real") as caught:
        mdtf.derive(real + 1j)
    assert isinstance(caught.value, mdtf.MdtfError)
    # float64 beyond float32's range: refused with how many and how large, not turned into inf
    big = real.copy()
    big[1, 2, 3], big[0, 0, 0] = 1e39, -5e40
    with pytest.raises(mdtf.MdtfValueError, match=r"2 value\(s\) up to 5e\+40 exceed float32's range"):
        mdtf.write(tmp_path / "big.nii", big)
    assert not (tmp_path / "big.nii").exists()
    # an infinity that was one already is not an overflow: written as it is
    inf = real.copy()
    inf[0, 0, 0] = np.inf
    mdtf.write(tmp_path / "inf.nii", inf)
    assert np.isinf(np.asarray(nibabel.load(tmp_path / "inf.nii").dataobj)[0, 0, 0])
    # fields, channels and a mask of different shapes
    with pytest.raises(ValueError, match=r"share one \(z, y, x\) shape: a \(4, 5, 6\), b \(4, 5, 7\)"):
        mdtf.write(tmp_path / "two.nii", {"a": real, "b": np.zeros((4, 5, 7))})
    with pytest.raises(mdtf.MdtfValueError, match="mask"):
        mdtf.histogram({"v": real}, mask=np.ones((4, 5, 5), bool))


def test_a_read_error_names_the_file_once(tmp_path: Path) -> None:
    bad = tmp_path / "bad.nii"
    bad.write_bytes(b"\0" * 400)
    with pytest.raises(mdtf.MdtfError) as caught:
        mdtf.read(bad)
    assert str(caught.value).count(str(bad)) == 1, str(caught.value)


def test_one_item_may_be_named_alone() -> None:
    # a plain string is one item, not its letters ('f2' is not 'f' and '2')
    a = np.zeros((6, 6, 6), np.float32)
    a[3:] = 1.0
    one = mdtf.derive(a, items="f2")
    listed = mdtf.derive(a, items=["f2"])
    assert list(one) == ["f2"] and np.array_equal(one["f2"], listed["f2"])


def test_writing_to_an_extension_mdtf_does_not_write_says_what_it_writes(tmp_path: Path) -> None:
    with pytest.raises(mdtf.MdtfError) as caught:
        mdtf.write(tmp_path / "x.png", np.zeros((4, 4, 4), np.float32))
    assert "no format mdtf writes" in str(caught.value) and ".nii.gz" in str(caught.value)
    assert not (tmp_path / "x.png").exists()
