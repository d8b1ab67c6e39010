"""validate-asset never certifies a dead rig: the clip a driver reads (named, or chosen and
said), the rig rules (WP-WGT-004 .. 009) on RobotExpressive and the demo, batch marking a dead
rig failed, poses named by what drives them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from wrinkle_setups import ROBOT, write_face_clips, write_robot_clip_setup

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.drivers.base import MorphClip, MorphTrack
from wrinklepipe.drivers.clips import choose_clip
from wrinklepipe.drivers.poses import pose_name, seconds
from wrinklepipe.gltf.animation import read_morph_clips
from wrinklepipe.io.confine import allowed_roots

needs_robot = pytest.mark.skipif(not ROBOT.is_file(), reason="../shared/data is absent")


def clip(name: str, index: int, values: list[list[float]]) -> MorphClip:
    track = MorphTrack(("a", "b"), np.arange(len(values), dtype=np.float64), np.array(values))
    return MorphClip(name, index, (track,))


def test_the_clip_named_else_the_first_that_moves_the_inputs_else_the_first():
    idle = clip("Idle", 0, [[0, 0], [0, 0]])
    wave = clip("Wave", 1, [[0, 0], [0, 1]])  # moves b only
    talk = clip("Talk", 2, [[0, 0], [1, 0]])  # moves a
    clips = [idle, wave, talk]
    chosen, c = choose_clip(clips, None, ["a"], "f.glb")
    assert chosen is talk and c.implicit and c.clips_moving == ("Talk",) and c.moving == ("a",)
    assert "chosen: the first of 3 clips that moves the inputs; 1 do" in c.describe()
    chosen, c = choose_clip(clips, "Idle", ["a"], "f.glb")
    assert chosen is idle and c.named and not c.implicit and c.moving == ()
    assert choose_clip(clips, 1, ["a"], "f.glb")[0] is wave  # an index names a clip too
    chosen, c = choose_clip([idle, clip("Rest", 1, [[0, 0]])], None, ["a"], "f.glb")
    assert chosen is idle and "none moves the inputs" in c.describe()
    assert not choose_clip([talk], None, ["a"], "f.glb")[1].implicit  # its only clip
    with pytest.raises(ValueError, match="'Run' is not an animation of f.glb.*'Idle', 'Wave'"):
        choose_clip(clips, "Run", ["a"], "f.glb")


def test_a_performance_files_clips_are_read_by_name(tmp_path):
    clips = read_morph_clips(write_face_clips(tmp_path / "faces.glb"))
    assert [(c.name, c.index) for c in clips] == [("Idle", 0), ("Talk", 1)]
    assert clips[0].moving() == () and clips[1].moving(["Angry", "Sad"]) == ("Angry",)


@needs_robot
def test_robotexpressive_has_14_clips_and_none_moves_a_morph_weight():
    clips = read_morph_clips(ROBOT)
    assert len(clips) == 14 and clips[0].name == "Dance"
    assert not any(c.moving() for c in clips)


def _convert(manifest: Path, out: Path, capsys) -> tuple[int, list[str]]:
    with allowed_roots([ROBOT.parent]):
        code = main(["convert", str(manifest), "-o", str(out), "--no-render"])
    err = capsys.readouterr().err.replace("\n ", " ")
    said = [ln for ln in err.splitlines() if ln.startswith(("error ", "warning ", "note: "))]
    return code, said


@needs_robot
def test_a_dead_blendshape_driver_fails_in_one_line_and_the_right_clip_passes(tmp_path, capsys):
    dead = write_robot_clip_setup(tmp_path / "dead")  # RobotExpressive's own 14 clips
    code, said = _convert(dead, tmp_path / "out_dead", capsys)
    assert code == 1
    issues = [s for s in said if not s.startswith("note: ")]
    assert len(issues) == 1, said  # one line: the driver, its clip, the regions never driven
    line = issues[0]
    # the notes that matter are on the terminal too: the head's UVs were generated
    assert any(s.startswith("note: Head/1: no UVs: added TEXCOORD_0") for s in said), said
    assert line.startswith("error WP-WGT-004: no pose of any driver activates a region")
    assert "driver 'blendshapes'" in line and "Angry, Surprised stay 0" in line
    assert "clip 'Dance' of RobotExpressive.glb (chosen: the first of 14 clips" in line
    assert line.endswith("regions never driven: brow_L, brow_R, mouth")
    report = json.loads((tmp_path / "out_dead" / "report.json").read_text())
    # nothing in the report contradicts the manifest: it has expressions, it is the driver
    # that is dead
    assert not any("no expressions" in n for n in report["notes"])
    # the same manifest reading the performance that moves them, clip named: passes
    named = write_robot_clip_setup(tmp_path / "named", "faces.glb", "Talk")
    write_face_clips(named.parent / "faces.glb")
    code, said = _convert(named, tmp_path / "out_named", capsys)
    assert code == 0, said
    assert not [s for s in said if not s.startswith("note: ")], said
    note = "note: drivers[0] (blendshapes) read clip 'Talk' of faces.glb (named in the manifest)"
    assert note in said
    report = json.loads((tmp_path / "out_named" / "report.json").read_text())
    poses = [p["pose"] for p in report["fidelity"]["png"]["poses"]]
    assert poses == ["Angry @ 1.0 s", "Surprised @ 3.0 s"]  # named by what drives them
    assert any("read clip 'Talk'" in n for n in report["key_notes"])
    page = (tmp_path / "out_named" / "report.html").read_text()
    assert "<b>Note:</b> drivers[0] (blendshapes) read clip &#x27;Talk&#x27; of faces.glb" in page
    # not named: the first clip that moves the inputs is read, and said once
    implicit = write_robot_clip_setup(tmp_path / "implicit", "faces.glb")
    write_face_clips(implicit.parent / "faces.glb")
    code, said = _convert(implicit, tmp_path / "out_implicit", capsys)
    assert code == 0
    said = [s for s in said if not s.startswith("note: Head/1")]
    assert [s[:22] for s in said] == ["warning WP-WGT-007: dr"], said
    assert "clip 'Talk' of faces.glb (chosen: the first of 2 clips" in said[0]


def zero_curves_demo(folder: Path, alive: bool) -> Path:
    """The 64 demo driven by keyed curves: all zero, or raising two regions."""
    m = write_demo_source(folder, 64)
    text = m.read_text()
    peak = 1.0 if alive else 0.0
    text = text[: text.index("[[drivers]]")] + (
        '[[drivers]]\nkind = "curves"\n[drivers.keys]\n'
        f"forehead_inner_l = [[0.0, 0.0], [1.0, {peak}], [2.0, 0.0]]\n"
        f"glabella = [[0.0, 0.0], [2.0, {peak}]]\n"
    )
    m.write_text(text)
    return m


def test_an_all_zero_curves_driver_on_the_demo_fails_and_batch_marks_it_failed(tmp_path, capsys):
    dead = zero_curves_demo(tmp_path / "src" / "dead", alive=False)
    code, said = _convert(dead, tmp_path / "out", capsys)
    assert code == 1
    errors = [s for s in said if s.startswith("error")]
    assert len(errors) == 1 and errors[0].startswith("error WP-WGT-004")
    assert "driver 'curves' (curves): its curves forehead_inner_l, glabella stay 0" in errors[0]
    # batch: the dead one fails validation, one that drives its regions passes (its other
    # regions are reported, not failed)
    zero_curves_demo(tmp_path / "src" / "alive", alive=True)
    code = main(
        ["batch", str(tmp_path / "src"), "-o", str(tmp_path / "batch"), "--no-render", "-j", "1"]
    )
    err = capsys.readouterr().err
    assert code == 1
    assert any(ln.startswith("failed dead") and "WP-WGT-004" in ln for ln in err.splitlines())
    assert any(ln.startswith("passed alive") for ln in err.splitlines()), err


def test_poses_are_named_by_what_drives_them():
    assert seconds(1.0) == "1.0" and seconds(1.25) == "1.25" and seconds(1 / 24) == "0.042"
    assert pose_name({"Surprised": 1.0}, ["mouth"], 1.0) == "Surprised @ 1.0 s"
    assert pose_name({"Sad": 0.2, "Angry": 0.9}, ["brow_L"], 2.5) == "Angry + Sad @ 2.5 s"
    assert pose_name({}, ["brow_L", "brow_R"], 1.0) == "brow_L, brow_R peak @ 1.0 s"


@needs_robot
def test_batch_marks_the_dead_robot_failed_and_the_named_clip_passed(tmp_path, capsys):
    """batch over the dead RobotExpressive and the one whose clip is named (the robot read
    through --allow-root: the worker processes honour it)."""
    dead = write_robot_clip_setup(tmp_path / "src" / "dead")
    named = write_robot_clip_setup(tmp_path / "src" / "named", "faces.glb", "Talk")
    write_face_clips(named.parent / "faces.glb")
    for m in (dead, named):  # batch finds the manifests that declare themselves
        m.write_text('schema = "wrinklepipe/manifest@1"\n' + m.read_text())
    args = ["batch", str(tmp_path / "src"), "-o", str(tmp_path / "out"), "--no-render", "-j", "1"]
    code = main([*args, "--allow-root", str(ROBOT.parent), "--report", str(tmp_path / "s.json")])
    err = capsys.readouterr().err.splitlines()
    assert code == 1, "\n".join(err)
    assert any(ln.startswith("failed dead") and "WP-WGT-004" in ln for ln in err), err
    assert any(ln.startswith("passed named") for ln in err), err
    assets = {a["id"]: a for a in json.loads((tmp_path / "s.json").read_text())["assets"]}
    assert assets["dead/manifest"]["exit_code"] == 1
    assert [
        i["data"]["regions"] for i in assets["dead/manifest"]["issues"] if i["code"] == "WP-WGT-004"
    ] == [["brow_L", "brow_R", "mouth"]]
    assert assets["named/manifest"]["exit_code"] == 0
