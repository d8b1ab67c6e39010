"""Issue 39, USD sources: every path a USD source names is confined to its folder where the file
is opened (asset-valued attributes, ``info:*``, textures, value clips, payloads, references,
sublayers), the usdz packs only what the confined stage resolved, and composition errors
(missing or cyclic sublayers, references, payloads) are issues WP-USD-xxx naming the layer,
with USD's own diagnostics never printed raw."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import pytest
from test_usd_layer import write_avatar
from wrinkle_setups import write_setup

from wrinklepipe.cli import main
from wrinklepipe.errors import InputError
from wrinklepipe.io.confine import allowed_roots, confine_usd

pxr = pytest.importorskip("pxr")

SECRET = b"secret bytes outside the asset folder\n"


@pytest.fixture
def avatar(tmp_path) -> tuple[Path, Path]:
    """(manifest, avatar.usda) in ``tmp_path/asset``, and a file outside it,
    ``tmp_path/outside/secret.png``."""
    folder = tmp_path / "asset"
    usd = write_avatar(folder)
    manifest = write_setup(folder, Path(usd.name), "hero", material="Skin", meshes=["Head"])
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "secret.png").write_bytes(SECRET)
    return manifest, usd


def _add_to_avatar(usd: Path, inside: str = "", metadata: str = "", after: str = "") -> None:
    """Author ``inside`` (properties) / ``metadata`` on the SkelRoot prim ``Avatar``, or
    ``after`` (prims) at the end of the layer."""
    text = usd.read_text()
    if metadata:
        text = text.replace('(kind = "component")', f'(kind = "component"\n{metadata})')
    if inside:
        text = text.replace('(kind = "component") {', f'(kind = "component") {{\n{inside}', 1)
    usd.write_text(text + after)


def _convert(manifest: Path, out: Path, *extra: str) -> int:
    return main(["convert", str(manifest), "-o", str(out), "--no-render", *extra])


def _one_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Warning: in" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in err, err
    return err


# ------------------------------------------------------------------------------------------------
# confinement: each kind of path, outside the folder, is refused before anything is read


@pytest.mark.parametrize(
    "kind",
    ["info_doc", "texture_absolute", "texture_dotdot", "texture_symlink", "clips", "asset_array"],
)
def test_a_path_outside_the_folder_is_refused_naming_layer_and_spec(avatar, tmp_path, capsys, kind):
    manifest, usd = avatar
    secret = tmp_path / "outside" / "secret.png"
    if kind == "info_doc":
        _add_to_avatar(usd, inside=f"    asset info:doc = @{secret}@\n")
        where = "</Avatar>.info:doc"
    elif kind == "texture_absolute":
        usd.write_text(usd.read_text().replace("@textures/skin.png@", f"@{secret}@"))
        where = "</Avatar/Looks/Skin/Albedo>.inputs:file"
    elif kind == "texture_dotdot":
        usd.write_text(usd.read_text().replace("@textures/skin.png@", "@../outside/secret.png@"))
        where = "</Avatar/Looks/Skin/Albedo>.inputs:file"
    elif kind == "texture_symlink":
        (usd.parent / "textures" / "link.png").symlink_to(secret)
        usd.write_text(usd.read_text().replace("@textures/skin.png@", "@textures/link.png@"))
        where = "</Avatar/Looks/Skin/Albedo>.inputs:file"
    elif kind == "clips":
        clip = tmp_path / "outside" / "clip.usda"
        clip.write_text('#usda 1.0\ndef Xform "Clip" { double3 xformOp:translate = (9, 9, 9) }\n')
        _add_to_avatar(
            usd,
            metadata=(
                "    clips = { dictionary default = {\n"
                f"        asset[] assetPaths = [@{clip}@]\n"
                '        string primPath = "/Clip"\n'
                "        double2[] active = [(0, 0)]\n"
                "    } }\n"
            ),
        )
        where = "</Avatar> clips"
    else:
        _add_to_avatar(
            usd, inside=f"    custom asset[] extraFiles = [@textures/skin.png@, @{secret}@]\n"
        )
        where = "</Avatar>.extraFiles"
    out = tmp_path / "out"
    assert _convert(manifest, out) == 2
    _one_error(capsys, "avatar.usda", "is outside", where, "--allow-root")
    assert not out.exists()


@pytest.mark.parametrize("arc", ["sublayer", "reference", "payload"])
def test_a_layer_outside_the_folder_is_refused_before_it_is_opened(avatar, tmp_path, capsys, arc):
    manifest, usd = avatar
    other = tmp_path / "outside" / "other.usda"
    other.write_text('#usda 1.0\ndef Xform "Other" {}\n')
    if arc == "sublayer":
        usd.write_text(
            usd.read_text().replace(
                "(\n    defaultPrim", f"(\n    subLayers = [@{other}@]\n    defaultPrim", 1
            )
        )
    else:
        key = "references" if arc == "reference" else "payload"
        _add_to_avatar(usd, after=f'\ndef Xform "Extra" ({key} = @{other}@</Other>) {{}}\n')
    assert _convert(manifest, tmp_path / "out") == 2
    _one_error(capsys, "is outside", "other.usda")


def test_a_nested_layer_is_confined_too(avatar, tmp_path, capsys):
    """A layer inside the folder that names a file outside: its own paths are checked."""
    manifest, usd = avatar
    inner = usd.parent / "inner.usda"
    secret = tmp_path / "outside" / "secret.png"
    inner.write_text(f'#usda 1.0\ndef Xform "Inner" {{\n    asset info:doc = @{secret}@\n}}\n')
    _add_to_avatar(usd, after='\ndef Xform "Extra" (references = @./inner.usda@</Inner>) {}\n')
    assert _convert(manifest, tmp_path / "out") == 2
    _one_error(capsys, "inner.usda", "</Inner>.info:doc", "is outside")


def test_allow_root_lets_an_outside_texture_in_and_the_usdz_packs_it(avatar, tmp_path, capsys):
    manifest, usd = avatar
    secret = tmp_path / "outside" / "secret.png"
    _add_to_avatar(usd, inside=f"    asset info:doc = @{secret}@\n")
    out = tmp_path / "out"
    assert _convert(manifest, out, "--allow-root", str(secret.parent)) in (0, 1)
    with zipfile.ZipFile(out / "hero.usdz") as z:
        packed = {n: z.read(n) for n in z.namelist()}
    assert packed["textures/source/secret.png"] == SECRET


def test_a_search_path_usd_would_find_beside_the_current_folder_is_refused(
    avatar, tmp_path, capsys
):
    """A search path (``nowhere.png``, no such file beside the layer) that USD's resolver finds
    in the current folder is refused; with no such file anywhere it is left as it is and the
    usdz packs nothing for it."""
    manifest, usd = avatar
    _add_to_avatar(usd, inside="    asset info:doc = @nowhere.png@\n")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    here = os.getcwd()
    os.chdir(cwd)
    try:
        assert _convert(manifest, tmp_path / "out0") in (0, 1)
        capsys.readouterr()
        (cwd / "nowhere.png").write_bytes(SECRET)
        assert _convert(manifest, tmp_path / "out1") == 2
    finally:
        os.chdir(here)
    _one_error(capsys, "@nowhere.png@", "is outside")  # (the path resolved in the cwd)
    with zipfile.ZipFile(tmp_path / "out0" / "hero.usdz") as z:
        assert not [n for n in z.namelist() if "nowhere" in n]


def test_flattened_usdz_refuses_an_asset_outside_the_source_folder(avatar, tmp_path):
    """The packer itself checks: a stage composed from a source whose asset lies outside (the
    confinement above bypassed) packs nothing from outside."""
    from pxr import Usd

    from wrinklepipe.package import WrinklePackage
    from wrinklepipe.usd.layer import flattened_usdz

    _, usd = avatar
    secret = tmp_path / "outside" / "secret.png"
    _add_to_avatar(usd, inside=f"    asset info:doc = @{secret}@\n")
    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().subLayerPaths.append(str(usd))
    pkg = WrinklePackage.__new__(WrinklePackage)
    object.__setattr__(pkg, "textures", [])
    with pytest.raises(InputError, match="is outside"):
        flattened_usdz(stage, pkg, "hero", usd)


def test_confine_usd_lists_the_files_inside(avatar):
    _, usd = avatar
    files = confine_usd(usd)
    assert usd.resolve() in files and (usd.parent / "textures" / "skin.png").resolve() in files
    with allowed_roots([]):
        assert confine_usd(usd) == files


# ------------------------------------------------------------------------------------------------
# composition errors: issue codes naming the layer, no raw USD text


def _broken(usd: Path, case: str) -> tuple[str, str]:
    folder = usd.parent
    if case == "missing_sublayer":
        text = usd.read_text().replace(
            "(\n    defaultPrim", "(\n    subLayers = [@./gone.usda@]\n    defaultPrim", 1
        )
        usd.write_text(text)
        return "WP-USD-001", "gone.usda"
    if case == "sublayer_cycle":
        (folder / "loop.usda").write_text("#usda 1.0\n(\n    subLayers = [@./avatar.usda@]\n)\n")
        text = usd.read_text().replace(
            "(\n    defaultPrim", "(\n    subLayers = [@./loop.usda@]\n    defaultPrim", 1
        )
        usd.write_text(text)
        return "WP-USD-002", "loop.usda"
    if case == "missing_reference":
        _add_to_avatar(usd, after='\ndef Xform "Extra" (references = @./gone.usda@</X>) {}\n')
        return "WP-USD-003", "gone.usda"
    (folder / "b.usda").write_text('#usda 1.0\ndef Xform "B" (references = @./a.usda@</A>) {}\n')
    (folder / "a.usda").write_text('#usda 1.0\ndef Xform "A" (references = @./b.usda@</B>) {}\n')
    _add_to_avatar(usd, after='\ndef Xform "Extra" (references = @./a.usda@</A>) {}\n')
    return "WP-USD-004", "a.usda"


CASES = ["missing_sublayer", "sublayer_cycle", "missing_reference", "reference_cycle"]


@pytest.mark.parametrize("case", CASES)
def test_convert_reports_a_composition_error_as_an_issue(avatar, tmp_path, capsys, case):
    manifest, usd = avatar
    code, layer = _broken(usd, case)
    out = tmp_path / "out"
    assert _convert(manifest, out) == 1  # written; validation found the error
    err = capsys.readouterr().err
    assert "Warning:" not in err and "_ReportErrors" not in err and "Traceback" not in err, err
    assert f"error {code}" in err, err
    report = json.loads((out / "report.json").read_text())
    issues = [i for i in report["validation"]["issues"] if i["code"] == code]
    assert issues, report["validation"]["issues"]
    assert any(layer in i["message"] for i in issues) and all(i["pointer"] for i in issues)


@pytest.mark.parametrize("case", CASES)
def test_validate_asset_reports_a_composition_error(avatar, tmp_path, capsys, case):
    manifest, usd = avatar
    out = tmp_path / "out"
    assert _convert(manifest, out) in (0, 1)
    capsys.readouterr()
    code, layer = _broken(usd, case)  # broken after the conversion: the layer over it sees it
    report = tmp_path / "report.json"
    args = ["validate-asset", str(out / "hero.usda"), "--no-render", "--report", str(report)]
    rc = main([*args, "--allow-root", str(usd.parent)])
    err = capsys.readouterr().err
    assert "Warning:" not in err and "_ReportErrors" not in err and "Traceback" not in err, err
    issues = [i for i in json.loads(report.read_text())["issues"] if i["code"] == code]
    assert rc == 1 and issues and any(layer in i["message"] for i in issues), err


def test_usd_diagnostics_are_captured_per_block_and_never_printed(tmp_path, capfd):
    from pxr import Usd

    from wrinklepipe.io.usd_diagnostics import captured_diagnostics, quiet

    layer = tmp_path / "a.usda"
    layer.write_text("#usda 1.0\n(\n    subLayers = [@./gone.usda@]\n)\n")
    with captured_diagnostics() as outer:
        with captured_diagnostics() as inner:
            Usd.Stage.Open(str(layer))
        with captured_diagnostics() as empty:
            pass
        quiet(Usd.Stage.Open)(str(layer))  # said inside its own block: neither outer's nor ours
    assert len(inner) == 1 and "gone.usda" in inner[0] and "instantiating" not in inner[0]
    assert empty == [] and outer == []
    assert "Warning" not in capfd.readouterr().err


# ------------------------------------------------------------------------------------------------
# a layer that cannot be read: one line in plain words, not USD's C++ error text


@pytest.mark.parametrize("damage", ["missing", "parse", "usdc", "usdc_short"])
@pytest.mark.parametrize("verb", ["inspect", "convert", "validate-asset"])
def test_a_layer_that_cannot_be_read_is_one_plain_line(tmp_path, capsys, damage, verb):
    folder = tmp_path / "asset"
    folder.mkdir()
    layer = folder / ("head.usdc" if damage.startswith("usdc") else "head.usda")
    if damage == "parse":
        layer.write_text('#usda 1.0\ndef Xform "A" {\n    asset x = @oops\n}\n')
        said = "head.usda:3:"
    elif damage == "usdc":
        layer.write_bytes(b"PXR-USDC" + bytes(range(256)) * 4)
        said = "corrupt"
    elif damage == "usdc_short":
        layer.write_bytes(b"PXR-USDC\0\0\0\0")
        said = "too small"
    else:
        said = "not found"
    manifest = write_setup(folder, Path(layer.name), "hero")
    target = {"inspect": layer, "convert": manifest, "validate-asset": manifest}[verb]
    args = [verb, str(target)] + (["-o", str(tmp_path / "out")] if verb == "convert" else [])
    assert main(args) == 2
    err = _one_error(capsys, said)
    assert "pxrInternal" not in err and "Error in '" not in err and ".cpp" not in err, err
    assert "pegtl" not in err and "parse error matching" not in err, err


@pytest.mark.parametrize(
    ("pattern", "value", "place"),
    [
        (r"point3f\[\] points = \[\(", "point3f[] points = [(nan, ", "in </Avatar/Head.points>"),
        (
            r"int\[\] faceVertexCounts = \[[^\]]*\]",
            "int[] faceVertexCounts = [4294967297]",
            "in </Avatar/Head.faceVertexCounts>",
        ),
    ],
)
def test_a_value_usd_cannot_parse_is_said_once_with_its_place(
    avatar, capsys, pattern, value, place
):
    """USD quotes the text it could not parse (a whole points array) and says some errors twice
    (with and without layer:line:column): the quote is cut short and the error said once, so
    the prim and property it names still fit the line (they were cut off at 300 characters)."""
    import re

    _, usd = avatar
    usd.write_text(re.sub(pattern, value, usd.read_text(), count=1))
    assert main(["inspect", str(usd)]) == 2
    err = _one_error(capsys, "cannot open USD stage", place)
    line = next(ln for ln in err.splitlines() if ln.startswith("error:"))
    assert line.count("Error parsing shaped value") <= 1 and "1.3, 0.1), (0, 1.5" not in line, line
