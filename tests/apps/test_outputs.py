"""volsmpl.apps.outputs and volsmpl.apps.progress: bodies and meshes in the input's frame, bars only on a terminal."""
import numpy as np
import pytest
import torch
import trimesh

from volsmpl.apps.outputs import body_record, mesh_path, to_input_frame, write_mesh
from volsmpl.apps.progress import progress, steps_bar
from volsmpl.scene.scan import from_y_up, to_y_up


def test_from_y_up_inverts_to_y_up():
    p = np.random.default_rng(0).normal(size=(20, 3))
    for up in ("y", "z"):
        assert np.allclose(from_y_up(to_y_up(p, up), up), p)
    # hand-computed: Y-up (1, 2, 3) is z-up (1, -3, 2): x kept, the file's z is our y, the file's y is our -z
    assert from_y_up(np.array([[1.0, 2.0, 3.0]]), "z").tolist() == [[1.0, -3.0, 2.0]]


def test_to_input_frame_units():
    assert np.allclose(to_input_frame([[0.5, 1.0, -0.25]], "cm", "y"), [[50.0, 100.0, -25.0]])
    with pytest.raises(ValueError, match="units"):
        to_input_frame([[0, 0, 0]], "in", "y")


@pytest.mark.parametrize("suffix", [".ply", ".obj"])
def test_write_mesh_reads_back_in_input_frame(tmp_path, suffix):
    box = trimesh.creation.box(extents=(0.2, 0.4, 0.6))
    path = write_mesh(tmp_path / f"m{suffix}", box.vertices, box.faces, units="mm", up="z")
    back = trimesh.load(path, process=False)
    ext = back.vertices.max(0) - back.vertices.min(0)
    assert np.allclose(ext, [200.0, 600.0, 400.0])   # mm; our y (0.4 m) is the file's z, our z (0.6 m) its y
    assert len(back.faces) == len(box.faces)
    with pytest.raises(ValueError, match="faces index"):
        write_mesh(tmp_path / "bad.ply", box.vertices[:3], box.faces)


def test_body_record_joints_and_params(tmp_path):
    from volsmpl.body import create_body

    body = create_body()
    transl = torch.tensor([[0.1, 0.2, 0.3]])
    out = body(transl=transl)
    rec = body_record(out, 0, units="cm", up="y")
    j = out.joints[0].detach().numpy() * 100.0
    assert np.allclose(rec["joints"][body.joint_names[0]], j[0], atol=1e-4)
    assert np.allclose(rec["pelvis"], j[0], atol=1e-4)
    assert rec["params"]["transl"] == pytest.approx([0.1, 0.2, 0.3])
    again = body(**{k: torch.tensor([v]) for k, v in rec["params"].items()})   # the params rebuild the same body
    assert torch.allclose(again.vertices, out.vertices, atol=1e-5)
    assert mesh_path(tmp_path, "my room", "volsmpl").parent.name.startswith("my_room-")


def test_progress_only_on_a_terminal(capsys):
    assert list(progress(range(3), "x")) == [0, 1, 2]      # pytest's stderr is no terminal: the plain iterable
    assert isinstance(progress([1], "x"), list)
    assert capsys.readouterr().err == ""
    assert steps_bar(True) is False and steps_bar(False) is None
