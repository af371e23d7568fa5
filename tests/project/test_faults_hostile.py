"""The fault suite, part 3 (issue: hardening 3): a job folder, a spec or a dataset made by someone
else cannot be turned against the user who runs the toolkit on it, and no input ends in a
traceback. Each case asserts the exit status (or the error type a command maps to exit 2), the
one-line message, and what is left behind; docs/testing.md#security says what is promised.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

from vrformats.atomic import replacing, temp_name, write_json_atomic, write_nofollow
from vrformats.errors import UserError
from vrformats.lifetime import FolderLock
from cli_errors import exit_code


# ---------------------------------------------------------------------------------------------
# links: nothing the toolkit writes goes through a link it did not make


def _victim(tmp_path) -> Path:
    v = tmp_path / "victim.txt"
    v.write_text("precious\n")
    return v


@pytest.mark.parametrize("what", ["link", "folder"])
def test_a_lock_that_is_a_link_or_a_folder_is_refused(tmp_path, what):
    victim = _victim(tmp_path)
    job = tmp_path / "job"
    job.mkdir()
    if what == "link":
        (job / ".lock").symlink_to(victim)
    else:
        (job / ".lock").mkdir()
    with pytest.raises(UserError) as e:
        FolderLock(job, "synth render").acquire()
    msg = str(e.value)
    assert "\n" not in msg and str(job / ".lock") in msg
    assert ("symbolic link" in msg) if what == "link" else ("is a folder" in msg)
    assert victim.read_text() == "precious\n"  # not truncated, no pid written into it
    assert (job / ".lock").is_symlink() if what == "link" else (job / ".lock").is_dir()


def test_a_render_into_a_job_folder_with_a_planted_lock_link_exits_2(tmp_path, capsys):
    from synth.cli import main as synth_main

    victim = _victim(tmp_path)
    spec = {"name": "lk", "out": str(tmp_path / "job"), "renderer": "fast", "size": [32, 24],
            "designs": [{"layouts": ["apt_0"], "path": {"name": "query", "frames": 3}}]}
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(spec))
    (tmp_path / "job").mkdir()
    (tmp_path / "job" / ".lock").symlink_to(victim)
    for extra in ([], ["--resume"]):
        assert synth_main(["render", str(tmp_path / "job.yaml"), "--quiet", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "symbolic link" in err, err
    assert victim.read_text() == "precious\n"
    assert sorted(p.name for p in (tmp_path / "job").iterdir()) == [".lock"]  # nothing rendered


def test_an_atomic_write_replaces_a_planted_link_and_ignores_a_planted_temporary_link(tmp_path):
    victim = _victim(tmp_path)
    target = tmp_path / "out" / "results.json"
    target.parent.mkdir()
    target.symlink_to(victim)  # a link where the file goes: replaced, not followed
    temp_name(target).symlink_to(tmp_path / "victim.txt")  # a link where the temporary file goes
    write_json_atomic(target, {"a": 1})
    assert victim.read_text() == "precious\n"
    assert not target.is_symlink() and target.read_text().startswith("{")
    assert not os.path.lexists(temp_name(target))
    folder = tmp_path / "out" / "dir.json"
    folder.mkdir()
    with pytest.raises(UserError, match="is a folder"):
        with replacing(folder) as tmp:
            tmp.write_text("x")


def test_job_files_and_logs_refuse_a_link(tmp_path):
    victim = _victim(tmp_path)
    log = tmp_path / "chunk.log"
    log.symlink_to(victim)
    with pytest.raises(UserError, match="symbolic link"):
        write_nofollow(log, "job\n")
    assert victim.read_text() == "precious\n"
    write_nofollow(tmp_path / "fresh.log", "ok\n")
    assert (tmp_path / "fresh.log").read_text() == "ok\n"


# ---------------------------------------------------------------------------------------------
# a hostile dataset stays inside its root (the ReplicaCAD-shaped fixture, damaged)

from tests.synth.sources.test_replicacad_bad_input import (SCENE, external_texture, import_error, object_glb, pristine, root,  # noqa: E402,F401
                                       scene_doc, urdf_glb)


def _object_config(root: Path) -> Path:
    for inst in scene_doc(root)["object_instances"]:
        base = inst["template_name"].rsplit("/", 1)[-1]
        hits = sorted((root / "configs/objects").rglob(f"{base}.object_config.json"))
        if hits:
            return hits[0]
    raise AssertionError("no object config")


def _set(config: Path, **fields) -> None:
    import json

    doc = json.loads(config.read_text())
    doc.update(fields)
    config.write_text(json.dumps(doc))


@pytest.mark.parametrize("where", ["absolute", "climbing", "secret"])
def test_a_render_asset_outside_the_root_is_refused(root, tmp_path, capsys, where):
    import shutil

    outside = tmp_path / "elsewhere"
    outside.mkdir()
    good = object_glb(root)
    shutil.copy(good, outside / "valid.glb")  # a valid GLB: it would import without the rule
    secret = tmp_path / "shadow"
    secret.write_text("root:$6$secret\n")
    cfg = _object_config(root)
    target = {"absolute": str(outside / "valid.glb"), "climbing": os.path.relpath(outside / "valid.glb", cfg.parent),
              "secret": str(secret)}[where]
    _set(cfg, render_asset=target)
    err = import_error(root, tmp_path, capsys)
    assert f"{cfg}: render_asset: " in err and "lies outside the dataset folder" in err and "SYNTH_ALLOW_OUTSIDE_ROOT" in err
    assert "secret" not in err.split("lies outside")[1]  # the file's content is never in the message
    if where == "absolute":  # allowed on purpose
        os.environ["SYNTH_ALLOW_OUTSIDE_ROOT"] = "1"
        try:
            assert synth_main_ok(root, tmp_path)
        finally:
            del os.environ["SYNTH_ALLOW_OUTSIDE_ROOT"]


def synth_main_ok(root, tmp_path) -> bool:
    from synth.cli import main as synth_main

    return synth_main(["scene", "import-replicacad", str(root), SCENE, "--out", str(tmp_path / "ok.yaml"),
                       "--allow-unknown"]) == 0


@pytest.mark.parametrize("uri", ["/etc/shadow", "../../../../../../../etc/passwd", "file:///etc/passwd", "OUTSIDE"])
def test_a_texture_uri_outside_the_root_is_refused(root, tmp_path, capsys, uri):
    from tests.synth.blender.test_gltf_render import glb_chunks, write_glb_chunks

    from synth.mesh.gltf import check_glb, clear_cache

    glb = object_glb(root)
    png = external_texture(glb)
    if uri == "OUTSIDE":  # a real PNG, outside the dataset
        (tmp_path / "tex.png").write_bytes(png.read_bytes())
        uri = str(tmp_path / "tex.png")
    doc, binary = glb_chunks(glb)
    doc["images"][0] = {"uri": uri}
    write_glb_chunks(glb, doc, binary)
    clear_cache()
    with pytest.raises(SceneFormatError) as e:
        check_glb(glb)
    assert e.value.field == "images[0].uri" and len(str(e.value).splitlines()) == 1
    assert ("lies outside the dataset folder" in str(e.value)) or ("scheme" in str(e.value))
    assert f"{glb}: images[0].uri: " in import_error(root, tmp_path, capsys)


def test_a_urdf_mesh_outside_the_root_is_refused(root, tmp_path, capsys):
    import xml.etree.ElementTree as ET

    glb = urdf_glb(root)
    urdf = next(glb.parent.glob("*.urdf"))
    text = urdf.read_text()
    mesh = next(ET.parse(urdf).iter("mesh")).get("filename")
    outside = tmp_path / "x" / "link.glb"
    outside.parent.mkdir()
    outside.write_bytes(glb.read_bytes())
    urdf.write_text(text.replace(f'filename="{mesh}"', f'filename="{outside}"', 1))
    err = import_error(root, tmp_path, capsys)
    assert str(urdf) in err and "lies outside the dataset folder" in err


from vrformats.errors import SceneFormatError  # noqa: E402


def test_a_layout_asset_name_cannot_climb_out_of_the_root(root, tmp_path):
    from synth.mesh.mesh_assets import asset_file
    from synth.mesh.urdf import urdf_path

    (tmp_path / "x.glb").write_bytes(b"glTF")
    for fn, name in ((asset_file, "replicacad:../x.glb"), (urdf_path, "replicacad-urdf:../../x.urdf")):
        with pytest.raises(SceneFormatError, match="lies outside the dataset folder") as e:
            fn(root, name) if fn is not asset_file else fn(root, name)
        assert name in str(e.value) and len(str(e.value).splitlines()) == 1


# ---------------------------------------------------------------------------------------------
# readers bound depth, size, text encoding and alias expansion

DEEP = 100_000


def _deep_yaml() -> str:
    return "a: " + "[" * DEEP + "]" * DEEP + "\n"


def _deep_json() -> str:
    return '{"a": ' + "[" * DEEP + "]" * DEEP + "}"


BOMB = "".join([
    "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n",
    *(f"a{k}: &a{k} [*a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}, *a{k - 1}]\n"
      for k in range(1, 9)),
])  # a8 expands to 10^9 values


def _one_line(capsys, code, want: str):
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and want in err, err
    assert "Traceback" not in err and len(err) < 600, err
    return err


CLI_SPECS = [  # (command, file name, extra args): every kind of YAML a user hands the CLI
    (["synth", "render"], "spec.yaml", ["--dry-run"]),
    (["reloc", "experiment"], "exp.yaml", []),
    (["reloc", "check"], "checks.yaml", ["RESULTS"]),
    (["synth", "scene", "show"], "layout.yaml", []),
    (["synth", "path", "show"], "path.yaml", []),
]


def _run(argv):
    from reloc.cli import main as reloc_main
    from synth.cli import main as synth_main

    return (synth_main if argv[0] == "synth" else reloc_main)(argv[1:])


@pytest.mark.parametrize("cmd, name, extra", CLI_SPECS, ids=[" ".join(c[0]) for c in CLI_SPECS])
@pytest.mark.parametrize("damage", ["deep", "latin1", "bomb_in_name"])
def test_hostile_yaml_is_one_line(tmp_path, capsys, cmd, name, extra, damage):
    f = tmp_path / name
    if name == "path.yaml":  # a saved path is PATH.txt + its PATH.yaml side file
        f = tmp_path / "p.yaml"
        (tmp_path / "p.txt").write_text("# timestamp tx ty tz qx qy qz qw\n0 0 0 1.5 0 0 0 1\n")
    if damage == "deep":
        f.write_text(_deep_yaml())
        want = "nested more than"
    elif damage == "latin1":
        f.write_bytes("name: caf\u00e9\n".encode("latin-1"))
        want = "not UTF-8 text: byte 0xE9"
    else:
        f.write_text(BOMB + "name: *a8\ndescription: *a8\n")
        want = "expands to more than"
    target = str(tmp_path / "p.txt") if name == "path.yaml" else str(f)
    extra = [str(tmp_path) if x == "RESULTS" else x for x in extra]
    err = _one_line(capsys, _run(cmd + [target] + extra), want)
    assert str(f) in err


@pytest.mark.parametrize("damage", ["deep", "latin1"])
@pytest.mark.parametrize("which", ["results.json", "scene_instance"])
def test_hostile_json_is_one_line(root, tmp_path, capsys, damage, which):
    data = _deep_json().encode() if damage == "deep" else '{"a": "caf\u00e9"}'.encode("latin-1")
    if which == "results.json":
        out = tmp_path / "exp"
        out.mkdir()
        (out / "results.json").write_bytes(data)
        code = _run(["reloc", "check", "demo_checks", str(out)])
        f = out / "results.json"
    else:
        f = root / f"configs/scenes/{SCENE}.scene_instance.json"
        f.write_bytes(data)
        code = _run(["synth", "scene", "import-replicacad", str(root), SCENE, "--out", str(tmp_path / "x.yaml")])
    err = _one_line(capsys, code, "nested more than" if damage == "deep" else "not UTF-8 text")
    assert str(f) in err


def test_readers_bound_size_depth_and_aliases(tmp_path, monkeypatch):
    import vrformats.yamlfile as yf
    from vrformats.yamlfile import read_json, read_yaml

    ok = tmp_path / "ok.yaml"
    ok.write_text("a: [1, 2, {b: 3}]\n")
    assert read_yaml(ok) == {"a": [1, 2, {"b": 3}]}
    monkeypatch.setattr(yf, "MAX_BYTES", 10)
    with pytest.raises(SceneFormatError, match="larger than"):
        read_yaml(ok)
    monkeypatch.undo()
    nest = tmp_path / "n.json"
    nest.write_text('{"a": ' + "[" * 70 + "]" * 70 + "}")  # deeper than MAX_DEPTH, but no RecursionError
    with pytest.raises(SceneFormatError, match="nested more than 64"):
        read_json(nest)


def test_the_fast_yaml_parser_reads_what_pyyaml_reads_and_errors_are_pyyamls(monkeypatch):
    """vrformats.yamlfile.safe_load parses with libyaml where PyYAML has it: every shipped YAML file gives
    the same values (types included) as yaml.safe_load, and a malformed document the same message."""
    import yaml

    import vrformats.yamlfile as yf

    repo = Path(__file__).resolve().parents[2]
    files = sorted(p for d in ("scenes", "render_jobs", "reloc", "synth") for p in (repo / d).rglob("*.yaml")
                   if p.stat().st_size < 8192 or p.name == "apt_1.yaml")  # the specs, presets and one layout
    assert len(files) > 20
    for f in files:
        text = f.read_text()
        assert repr(yf.safe_load(text)) == repr(yaml.safe_load(text)), f
    bad = "name: x\ndesigns: [\n"
    with pytest.raises(SceneFormatError) as fast:
        yf.parse_yaml("s.yaml", bad)
    monkeypatch.setattr(yf, "_FAST_LOADER", None)  # PyYAML without libyaml
    with pytest.raises(SceneFormatError) as plain:
        yf.parse_yaml("s.yaml", bad)
    assert str(fast.value) == str(plain.value) and "malformed YAML" in str(fast.value)


# ---------------------------------------------------------------------------------------------
# numbers from the user: range and finiteness where they are read; resources bounded


def _exit_code(argv) -> int:
    return exit_code(_run, argv)


@pytest.mark.parametrize("args, says", [
    (["--perturbation", "threads:99999999"], "from 1 to 256"),
    (["--perturbation", "jitter:1:100000"], "at most 255"),
    (["--max-spread", "-1"], "fraction from 0 to 1"),
    (["--max-spread", "nan"], "fraction from 0 to 1"),
    (["--max-tour-loss", "5"], "fraction from 0 to 1"),
    (["--workers", "100000"], "from 1 to 256"),
])
def test_stability_benchmark_options_are_bounded(capsys, args, says):
    code = _exit_code(["reloc", "bench", "stability", "demo_experiment", *args])
    _one_line(capsys, code, says)


def test_stability_benchmark_out_inside_a_render_folder_is_refused(tmp_path, capsys):
    job = tmp_path / "job"
    tour = job / "apt_0__day__query"
    tour.mkdir(parents=True)
    (job / "design.json").write_text("{}")
    (tour / "meta.json").write_text("{}")
    (tour / "poses.txt").write_text("")
    for out, what in ((job, "holds a rendered design ("), (tour, "lies inside a rendered tour ("),
                      (tour / "sub", "lies inside a rendered tour (")):
        code = _exit_code(["reloc", "bench", "stability", "demo_experiment", "--out", str(out)])
        err = _one_line(capsys, code, what)
        assert err.endswith("write the stability benchmark into another folder"), err
    assert sorted(p.name for p in job.rglob("*")) == ["apt_0__day__query", "design.json", "meta.json", "poses.txt"]


# ---------------------------------------------------------------------------------------------
# sensor files: bases


@pytest.mark.parametrize("case", ["self", "pair", "unknown"])
def test_sensor_bases_that_loop_or_do_not_exist_are_one_line(tmp_path, case):
    from vrformats.sensors import load_sensor

    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    if case == "self":
        a.write_text("name: a\nbase: a.yaml\nnoise_scale: 2\n")
        want = "a cycle of bases: a.yaml -> a.yaml"
    elif case == "pair":
        a.write_text("name: a\nbase: b.yaml\nnoise_scale: 2\n")
        b.write_text("name: b\nbase: a.yaml\nnoise_scale: 2\n")
        want = "a cycle of bases: a.yaml -> b.yaml -> a.yaml"
    else:
        a.write_text("name: a\nbase: kinect9\n")
        want = "unknown sensor preset 'kinect9'"
    with pytest.raises(SceneFormatError) as e:
        load_sensor(str(a))
    assert want in str(e.value) and len(str(e.value).splitlines()) == 1
    assert e.value.field == "base" and e.value.file in (str(a), str(b))
    if case == "unknown":
        assert e.value.file == str(a)


def test_a_sensor_base_file_is_found_next_to_the_sensor_file(tmp_path, monkeypatch):
    from vrformats.sensors import load_sensor

    d = tmp_path / "sensors"
    d.mkdir()
    (d / "noisy.yaml").write_text("name: noisy\nbase: structured_light\nnoise_scale: 2\n")
    (d / "noisier.yaml").write_text("name: noisier\nbase: noisy.yaml\nnoise_scale: 2\n")
    monkeypatch.chdir(tmp_path)  # not the sensor files' folder
    s = load_sensor(str(d / "noisier.yaml"))
    assert s.name == "noisier"


# ---------------------------------------------------------------------------------------------
# navmeshes and the stand-in tool


@pytest.mark.parametrize("setting, value", [("cell_size", 1e-9), ("agent_radius", 1e9), ("cell_size", float("nan"))])
def test_a_navmesh_with_hostile_settings_is_one_line(tmp_path, setting, value):
    import struct

    from replicacad_real_fixture import FILES
    from synth.sources.replicacad.navmesh import HEADER, PARAMS, SETTINGS, SETTINGS_NAMES, read_navmesh

    b = bytearray((FILES / "navmeshes" / "apt_0.navmesh").read_bytes())
    at = HEADER.size + PARAMS.size + 4 * SETTINGS_NAMES.index(setting)
    assert SETTINGS.size > 4 * SETTINGS_NAMES.index(setting)
    struct.pack_into("<f", b, at, value)
    p = tmp_path / "hostile.navmesh"
    p.write_bytes(bytes(b))
    with pytest.raises(SceneFormatError) as e:
        read_navmesh(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)
    assert f"settings.{setting}" in str(e.value) or "implausible" in str(e.value)


def test_a_failed_standin_build_leaves_nothing_and_links_out_are_refused(tmp_path, capsys):
    import subprocess
    import sys

    repo = Path(__file__).resolve().parents[2]
    src = tmp_path / "src"
    (src / "configs" / "stages").mkdir(parents=True)
    (src / "configs" / "stages" / "bad.stage_config.json").write_text("{not json")
    out = tmp_path / "out"
    tool = [sys.executable, str(repo / "tools" / "replicacad_standin.py")]
    p = subprocess.run(tool + [str(src), str(out)], capture_output=True, text=True)
    assert p.returncode != 0 and "Traceback" not in p.stderr, p.stderr
    assert not out.exists() and not (tmp_path / "out.building").exists()
    victim = _victim(tmp_path)
    (src / "configs" / "stolen.txt").symlink_to(victim)
    p = subprocess.run(tool + [str(src), str(out)], capture_output=True, text=True)
    assert p.returncode == 2 and "outside" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not (tmp_path / "out.building").exists()
    p = subprocess.run(tool + [str(src), str(out), "--ceiling", "nan"], capture_output=True, text=True)
    assert p.returncode == 2 and "--ceiling" in p.stderr


# ---------------------------------------------------------------------------------------------
# the dataset's semantic lexicon


@pytest.fixture(scope="module")
def real_root(tmp_path_factory) -> Path:
    from replicacad_real_fixture import write_real_fixture

    return write_real_fixture(tmp_path_factory.mktemp("rc_real")).resolve()


def test_a_duplicate_id_in_the_dataset_lexicon_is_refused(real_root, tmp_path, capsys):
    import json
    import shutil

    root = tmp_path / "rc"
    shutil.copytree(real_root, root)
    lex = root / "configs/ssd/replicaCAD_semantic_lexicon.json"
    doc = json.loads(lex.read_text())
    names = {c["name"]: c["id"] for c in doc["classes"]}
    doc["classes"].append({"name": "bed", "id": names["basket"]})  # apt_0's basket would import as a bed
    lex.write_text(json.dumps(doc))
    from synth.cli import main as synth_main

    code = synth_main(["scene", "import-replicacad", str(root), "apt_0", "--out", str(tmp_path / "a.yaml")])
    err = _one_line(capsys, code, f"id {names['basket']} ('bed') is already classes[")
    assert str(lex) in err and "'basket'" in err and not (tmp_path / "a.yaml").exists()


# ---------------------------------------------------------------------------------------------
# graded levels never merge silently


@pytest.mark.parametrize("levels, says", [(["0.5", "0.5000001"], "same level to the percent"),
                                          (["0.001", "0.004"], "same level to the percent"),
                                          (["0.0149", "0.0151"], "both move")])
def test_graded_levels_that_would_merge_are_refused(tmp_path, capsys, levels, says):
    from synth.cli import main as synth_main

    code = synth_main(["scene", "grade", "apt_0", "--levels", *levels, "--out", str(tmp_path / "g")])
    _one_line(capsys, code, says)
    assert not (tmp_path / "g").exists() or not any((tmp_path / "g").iterdir())


# ---------------------------------------------------------------------------------------------
# names and text that reach the terminal


@pytest.mark.parametrize("name, says", [("evil\x1b]0;pwned\x07\nname", "control or bidirectional"),
                                        ("abc\u202eexe.fdp", "control or bidirectional"),
                                        ("n" * 100_000, "a name of 100000 characters; at most 120"),
                                        (["x"], "expected a non-empty string")])
@pytest.mark.parametrize("where", ["render spec", "experiment spec", "lighting preset", "dimmer file", "layout"])
def test_names_are_bounded_and_printable(tmp_path, capsys, name, says, where):
    from vrformats.fields import MAX_NAME  # noqa: F401
    from reloc.experiments.spec import load_experiment
    from synth.jobs.spec import load_spec
    from synth.scene.lighting import load_lighting
    from synth.scene.model import load_layout

    f = tmp_path / "x.yaml"
    if where == "render spec":
        doc = {"name": name, "out": str(tmp_path / "o"), "designs": [{"layouts": ["apt_0"], "path": "query"}]}
        load = load_spec
    elif where == "experiment spec":
        doc = yaml.safe_load((Path(__file__).resolve().parents[2] / "reloc/specs/demo_experiment.yaml").read_text())
        doc["name"] = name
        load = load_experiment
    elif where == "lighting preset":
        doc, load = {"name": name, "sky": {"color": [0, 0, 0], "strength": 0}}, load_lighting
    elif where == "dimmer file":
        doc, load = {"name": name, "dimmer": 0.75}, load_lighting
    else:
        doc = yaml.safe_load((Path(__file__).resolve().parents[2] / "scenes/layouts/apt_0.yaml").read_text())
        doc["name"] = name
        load = load_layout
    f.write_text(yaml.safe_dump(doc, allow_unicode=True))
    with pytest.raises(UserError) as e:
        load(str(f))
    msg = str(e.value)
    assert says in msg and "name" in msg, msg
    from vrformats.fields import terminal_safe

    safe = terminal_safe(msg)
    assert "\x1b" not in safe and "\x07" not in safe and "\u202e" not in safe and "\n" not in safe
    assert len(msg) < 600


def test_error_lines_escape_what_a_file_says(tmp_path, capsys):
    from synth.cli import main as synth_main

    f = tmp_path / "spec.yaml"
    f.write_text(yaml.safe_dump({"name": "ok", "out": str(tmp_path / "o"), "designs": [{"layouts": ["\x1b[2J\x1b[31mgotcha"], "path": "query"}]}))
    code = synth_main(["render", str(f), "--dry-run"])
    err = capsys.readouterr().err
    assert code == 2 and "\x1b" not in err and "\\x1b" in err and len(err.strip().splitlines()) == 1, err


def test_a_glb_with_a_deeply_nested_json_chunk_is_one_line(tmp_path):
    import struct

    from synth.mesh.gltf import check_glb

    body = ('{"asset": {"version": "2.0"}, "extras": ' + "[" * DEEP + "]" * DEEP + "}").encode()
    body += b" " * (-len(body) % 4)
    glb = tmp_path / "deep.glb"  # a valid GLB 2.0 container around a 100,000-level JSON chunk
    glb.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(body)) + struct.pack("<II", len(body), 0x4E4F534A) + body)
    with pytest.raises(SceneFormatError) as e:
        check_glb(glb)
    assert str(glb) in str(e.value) and "nested" in str(e.value) and "\n" not in str(e.value)
