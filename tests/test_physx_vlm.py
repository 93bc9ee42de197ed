"""The PhysX VLM backend: the multi-turn protocol with a canned model (real ground-truth answers)
and with a randomly initialised tiny Qwen2.5-VL built offline (tokenizer trained on the real
prompts), plus registration."""

from __future__ import annotations

import numpy as np
import pytest

from generation.physx import register_backends
from generation.physx.protocol import ProtocolError
from scene_builder.model import JointType
from generation.physx.vlm import (
    ChatAnswer,
    PhysxConversation,
    PhysxPrompts,
    TransformersQwenVL,
    TruncatedAnswerError,
    VlmCallError,
    answer_token_budget,
    count_parts,
    object_crop,
    physx_from_conversation,
    run_conversation,
    truncation_problem,
)
from scene_builder.registry import Registry
from scene_builder.errors import InputError
from tests.conftest import PHYSX_PROTOCOL, require

ANY = PHYSX_PROTOCOL / "PhysX-Anything"


def _prompts() -> PhysxPrompts:
    d = require(ANY)
    return PhysxPrompts((d / "overall_prompt.txt").read_text(), (d / "41452_coord_0_question.txt").read_text())


class CannedCabinet:
    """Answers like the real model would, with the real ground-truth texts of object 41452; it
    checks that each request carries the protocol's history."""

    def __init__(self) -> None:
        self.requests: list[tuple[tuple[str, str], ...]] = []

    def generate(self, image_rgb, turns, max_new_tokens):
        self.requests.append(tuple(turns))
        if len(turns) == 1:
            return (ANY / "41452_basic_info.txt").read_text()
        question = turns[-1][1]
        k = int(question.split("description of l_")[1].split(",")[0])
        return (ANY / f"41452_coord_{k}.txt").read_text()


def test_canned_conversation_gives_part_grids_and_joint():
    prompts = _prompts()
    assert prompts.grid == 32
    chat = CannedCabinet()
    image = np.zeros((64, 64, 3), np.uint8)
    conv = run_conversation(chat, image, prompts)
    assert len(chat.requests) == 3  # description + one request per part
    description = (ANY / "41452_basic_info.txt").read_text()
    for k, req in enumerate(chat.requests[1:]):
        assert [r for r, _ in req] == ["user", "assistant", "user"]
        assert req[1][1] == description and f"l_{k}" in req[2][1] and req[0][1] == prompts.overall
    obj, report = physx_from_conversation(conv)
    assert report.clean, report.warnings
    door, frame = obj.part("cabinet_door"), obj.part("cabinet_frame")
    assert door.voxel_count == 519 and frame.voxel_count == 3517
    assert frame.parent is None and door.parent == "cabinet_frame"
    assert door.joint.type is JointType.REVOLUTE
    assert np.allclose(door.joint.axis, [0, 1, 0])  # PhysX +x (the door's width) is asset +y
    assert door.joint.lower == pytest.approx(np.radians(-122)) and door.joint.upper == 0.0
    assert np.allclose(obj.size_m, [0.40, 1.00, 0.80])  # Dimension 100*40*80 cm, front towards +x
    # the door is the front-most part
    assert door.voxel_centres_m()[:, 0].max() > frame.voxel_centres_m()[:, 0].max()
    assert obj.voxel_mass_kg == pytest.approx(700.0 * (519 + 3517) * float(np.prod(door.voxel_size_m)))


class BudgetedCabinet(CannedCabinet):
    """The real answers of object 41452, each cut to its budget (one token per character, an
    over-count of Qwen's digit tokens) and flagged as a model does when it stops at the budget.
    with_flag False: a plain string, as a model that cannot tell."""

    def __init__(self, with_flag: bool = True) -> None:
        super().__init__()
        self.budgets: list[int] = []
        self.with_flag = with_flag

    def generate(self, image_rgb, turns, max_new_tokens):
        full = super().generate(image_rgb, turns, max_new_tokens)
        self.budgets.append(max_new_tokens)
        text = full[:max_new_tokens]
        return ChatAnswer(text, hit_limit=len(full) > max_new_tokens, budget=max_new_tokens) if self.with_flag else text


def test_answer_budget_follows_the_grid_and_is_a_config_value():
    from scene_builder.config import GenerationConfig

    assert answer_token_budget(32) == 32768 and answer_token_budget(64) == 65536
    assert GenerationConfig().vlm_max_new_tokens == 0  # 0: follow the grid
    chat = BudgetedCabinet()
    run_conversation(chat, np.zeros((8, 8, 3), np.uint8), _prompts())
    assert chat.budgets == [32768, 32768, 32768]
    chat = BudgetedCabinet()
    run_conversation(chat, np.zeros((8, 8, 3), np.uint8), _prompts(), max_new_tokens=9000)
    assert chat.budgets == [9000, 9000, 9000]


def test_truncation_is_detected_in_the_real_answers_cut_anywhere_that_shows():
    description = (ANY / "41452_basic_info.txt").read_text() if ANY.exists() else ""
    require(ANY)
    coords = [(ANY / f"41452_coord_{k}.txt").read_text() for k in (0, 1)]
    assert truncation_problem(description, "description", 32) is None
    assert all(truncation_problem(c, "geometry", 32) is None for c in coords)
    # the description cut in the parts, in the group list, inside the last group's brackets
    for cut in (300, 450, 560, len(description) - 3):
        assert truncation_problem(description[:cut], "description", 32) is not None, cut
    # geometry cut mid-number: '388-40' of '388-402' (a reversed run), or right after the '-'
    words = coords[1].split()
    k = next(i for i in range(len(words) // 2, len(words)) if "-" in words[i] and len(set(map(len, words[i].split("-")))) == 1)
    head = " ".join(words[:k]) + " "
    assert "ends before it starts" in truncation_problem(head + words[k][:-1], "geometry", 32)
    assert "is cut" in truncation_problem(head + words[k].split("-")[0] + "-", "geometry", 32)
    assert "does not follow" in truncation_problem(head + words[k][:2], "geometry", 32)
    # Omni template RLE: cut inside a line, or after a whole line (the later layers are missing)
    omni = (PHYSX_PROTOCOL / "derived" / "41452_coord_1.SYNTHETIC-omni64.txt").read_text()
    assert truncation_problem(omni, "geometry", 64) is None
    assert truncation_problem(omni[: len(omni) // 2], "geometry", 64) is not None
    lines = omni.split("\n")
    assert "layers 41..63 missing" in truncation_problem("\n".join(lines[: lines.index(next(ln for ln in lines if ln.startswith("40:"))) + 1]), "geometry", 64)


def test_truncated_answer_is_asked_again_with_twice_the_budget():
    # l_1's real answer (6788 characters) does not fit in 4000: asked again with 8000, it does
    chat = BudgetedCabinet()
    conv = run_conversation(chat, np.zeros((8, 8, 3), np.uint8), _prompts(), max_new_tokens=4000)
    assert chat.budgets == [4000, 4000, 4000, 8000]
    assert len(conv.notes) == 1 and "l_1 geometry" in conv.notes[0] and "8000" in conv.notes[0]
    obj, _ = physx_from_conversation(conv)
    assert obj.part("cabinet_frame").voxel_count == 3517  # the far side is not lost
    # no retries left: a one-line error naming the part and the budget
    with pytest.raises(TruncatedAnswerError, match="l_1 geometry.*4000"):
        run_conversation(BudgetedCabinet(), np.zeros((8, 8, 3), np.uint8), _prompts(), max_new_tokens=4000, retries=0)
    # a model that cannot tell it stopped: the text itself shows the cut (mid-number here)
    cut = next(n for n in range(4000, 4100) if truncation_problem((ANY / "41452_coord_1.txt").read_text()[:n], "geometry", 32))
    chat = BudgetedCabinet(with_flag=False)
    conv = run_conversation(chat, np.zeros((8, 8, 3), np.uint8), _prompts(), max_new_tokens=cut)
    assert chat.budgets[-1] == 2 * cut and physx_from_conversation(conv)[0].part("cabinet_frame").voxel_count == 3517


def test_model_failure_is_a_vlm_call_error():
    class Broken:
        def generate(self, image_rgb, turns, max_new_tokens):
            raise RuntimeError("CUDA out of memory. Tried to allocate 2.00 GiB\nmore detail")

    with pytest.raises(VlmCallError, match="description: the model failed \\(RuntimeError: CUDA out of memory") as err:
        run_conversation(Broken(), np.zeros((8, 8, 3), np.uint8), _prompts())
    assert "\n" not in str(err.value)


def test_a_model_folder_that_does_not_load_is_one_vlm_call_error_raised_again_without_reloading(tmp_path):
    """Files present but broken (config.json not JSON; tokenizer.json without the keys
    transformers reads, which raises KeyError): one line naming the folder and the cause, and the
    same error for every later object."""
    from generation.physx import PhysxVlmGenerator

    for name, broken in (("config", {"config.json": "not json"}), ("tokenizer", {"tokenizer.json": '{"a": 1}'})):
        folder = tmp_path / name
        folder.mkdir()
        files = {"config.json": "{}", "preprocessor_config.json": "{}", "tokenizer.json": "{}", "model.safetensors": "garbage",
                 "overall_prompt.txt": "a", "geometry_question.txt": "b"} | broken
        for f, text in files.items():
            (folder / f).write_text(text)
        gen = PhysxVlmGenerator(folder)
        with pytest.raises(VlmCallError, match=f"cannot load the PhysX model from {folder}") as first:
            gen._model()
        assert "\n" not in str(first.value)
        (folder / "config.json").unlink()  # not read again: the first failure is kept
        with pytest.raises(VlmCallError) as again:
            gen._model()
        assert again.value is first.value


def test_object_crop_is_a_centred_single_object_512_image_on_black():
    rng = np.random.default_rng(0)
    rgb = rng.integers(1, 255, (300, 400, 3), dtype=np.uint8)
    mask = np.zeros((300, 400), dtype=bool)
    mask[40:140, 250:300] = True  # 100 tall, 50 wide, off-centre
    crop = object_crop(rgb, mask)
    assert crop.shape == (512, 512, 3) and crop.dtype == np.uint8
    lit = crop.max(axis=2) > 0
    rows, cols = np.nonzero(lit)
    assert rows.max() - rows.min() + 1 == pytest.approx(0.58 * 512, abs=2)  # longer side at the upstream fill
    assert cols.max() - cols.min() + 1 == pytest.approx(0.58 * 512 / 2, abs=2)
    assert (rows.min() + rows.max()) / 2 == pytest.approx(255.5, abs=1.5)
    assert (cols.min() + cols.max()) / 2 == pytest.approx(255.5, abs=1.5)
    # background (everything outside the mask, the cluttered room) is black
    assert not lit[:100].any() and not lit[:, :150].any()
    # the object's colours survive (mean within a few levels)
    assert np.abs(crop[lit].mean(axis=0) - rgb[mask].mean(axis=0)).max() < 8
    with pytest.raises(InputError):
        object_crop(rgb, np.zeros((300, 400), dtype=bool))


def test_count_parts_rule():
    assert count_parts("l_0: a\nl_1: b\nl_3: c") == 2
    assert count_parts("nothing") == 0


def test_garbage_description_is_a_clean_error():
    conv = PhysxConversation("Name: x\n<<garbage>> 12 ;;", (), 32)
    with pytest.raises(ProtocolError, match="no part line"):
        physx_from_conversation(conv)


def test_garbage_geometry_is_reported_not_a_crash():
    conv = PhysxConversation((ANY / "41452_basic_info.txt").read_text() if ANY.exists() else "", ("388-402 zz 99999", "§§§"), 32)
    require(ANY)
    obj, report = physx_from_conversation(conv)
    assert obj.part("cabinet_door").voxel_count == 15 and obj.part("cabinet_door").parent is None
    assert any("l_1 (Cabinet Frame): no voxels" in w for w in report.warnings)
    assert any("malformed token" in w for w in report.warnings)


def _tiny_qwen_vl(texts: list[str]):
    """A randomly initialised Qwen2.5-VL of ~60k parameters with a BPE tokenizer trained here."""
    import torch
    from tokenizers import Tokenizer, decoders, models, pre_tokenizers, trainers
    from transformers import PreTrainedTokenizerFast, Qwen2_5_VLConfig, Qwen2_5_VLForConditionalGeneration
    from transformers.models.qwen2_vl.image_processing_pil_qwen2_vl import Qwen2VLImageProcessorPil

    special = ["<|endoftext|>", "<|im_start|>", "<|im_end|>", "<|vision_start|>", "<|vision_end|>", "<|image_pad|>", "<|video_pad|>"]
    tok = Tokenizer(models.BPE())
    tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
    tok.decoder = decoders.ByteLevel()
    trainer = trainers.BpeTrainer(vocab_size=400, special_tokens=special, initial_alphabet=pre_tokenizers.ByteLevel.alphabet(), show_progress=False)
    tok.train_from_iterator(texts, trainer)
    # Qwen2-VL's chat template, reduced to text and image content
    template = (
        "{% for message in messages %}{% if loop.first and message['role'] != 'system' %}<|im_start|>system\n"
        "You are a helpful assistant.<|im_end|>\n{% endif %}<|im_start|>{{ message['role'] }}\n"
        "{% for content in message['content'] %}{% if content['type'] == 'image' %}<|vision_start|><|image_pad|><|vision_end|>"
        "{% elif content['type'] == 'text' %}{{ content['text'] }}{% endif %}{% endfor %}<|im_end|>\n{% endfor %}"
        "{% if add_generation_prompt %}<|im_start|>assistant\n{% endif %}"
    )
    tokenizer = PreTrainedTokenizerFast(tokenizer_object=tok, eos_token="<|im_end|>", pad_token="<|endoftext|>", additional_special_tokens=special[1:])
    tokenizer.chat_template = template
    ids = {t: tokenizer.convert_tokens_to_ids(t) for t in special}
    image_processor = Qwen2VLImageProcessorPil(size={"shortest_edge": 56 * 56, "longest_edge": 56 * 56}, patch_size=14, merge_size=2, temporal_patch_size=2)
    config = Qwen2_5_VLConfig(
        text_config=dict(
            vocab_size=len(tokenizer), hidden_size=32, intermediate_size=64, num_hidden_layers=2, num_attention_heads=2,
            num_key_value_heads=1, max_position_embeddings=4096,
            rope_parameters={"rope_type": "default", "rope_theta": 1e6, "mrope_section": [2, 3, 3]},
            bos_token_id=ids["<|endoftext|>"], eos_token_id=ids["<|im_end|>"], pad_token_id=ids["<|endoftext|>"],
        ),
        vision_config=dict(depth=1, hidden_size=32, intermediate_size=64, num_heads=2, out_hidden_size=32, patch_size=14,
                           spatial_merge_size=2, temporal_patch_size=2, window_size=56, fullatt_block_indexes=[0]),
        image_token_id=ids["<|image_pad|>"], video_token_id=ids["<|video_pad|>"],
        vision_start_token_id=ids["<|vision_start|>"], vision_end_token_id=ids["<|vision_end|>"],
    )
    torch.manual_seed(0)
    model = Qwen2_5_VLForConditionalGeneration(config).eval()
    return TransformersQwenVL(model, tokenizer, image_processor, image_size_px=56, max_total_tokens=4096)


@pytest.mark.slow
def test_tiny_random_qwen2_5_vl_runs_the_protocol_end_to_end():
    prompts = _prompts()
    description = (ANY / "41452_basic_info.txt").read_text()
    texts = [prompts.overall, prompts.geometry, description, (ANY / "41452_coord_0.txt").read_text()]
    chat = _tiny_qwen_vl(texts)
    image = (np.random.default_rng(0).random((48, 40, 3)) * 255).astype(np.uint8)
    answer = chat.generate(image, (("user", prompts.overall),), max_new_tokens=24)
    assert isinstance(answer, ChatAnswer) and answer == chat.generate(image, (("user", prompts.overall),), max_new_tokens=24)  # greedy
    # random weights never say "end of turn" in 24 tokens: the answer stopped at its budget
    assert answer.hit_limit is True and answer.budget == 24
    # the geometry turn with the real description in the history
    geometry = chat.generate(image, (("user", prompts.overall), ("assistant", description), ("user", prompts.geometry_question(1))), 24)
    assert isinstance(geometry.text, str)
    # the whole loop: the cut answer is asked again with 48 tokens, still cut: a clean one-line error
    with pytest.raises(TruncatedAnswerError, match="24, 48 tokens") as err:
        run_conversation(chat, image, prompts, max_new_tokens=24)
    assert "\n" not in str(err.value) and "description" in str(err.value)


def test_register_backends_reports_missing_weights(tmp_path, monkeypatch):
    monkeypatch.setenv("SCENE_BUILDER_MODELS", str(tmp_path))
    reg = Registry("generation")
    register_backends(reg)
    entry = reg.entries()[0]
    assert entry.name == "physx-anything-vlm" and entry.priority == 100
    reason = entry.available()
    assert reason is not None and "physx-anything" in reason and "\n" not in reason
    (tmp_path / "physx-anything").mkdir()
    for f in ("config.json", "preprocessor_config.json", "model.safetensors", "tokenizer.json", "overall_prompt.txt"):
        (tmp_path / "physx-anything" / f).write_text("{}")
    assert "geometry_question.txt" in entry.available()
    (tmp_path / "physx-anything" / "geometry_question.txt").write_text("q")
    assert entry.available() is None


@pytest.mark.slow
def test_canned_answers_become_an_articulated_asset_with_computed_mass():
    from generation.physx.convert import to_object_asset
    from scene_builder.config import GenerationConfig
    from scene_builder.model import AssetKind

    conv = run_conversation(CannedCabinet(), np.zeros((32, 32, 3), np.uint8), _prompts())
    obj, _ = physx_from_conversation(conv)
    cfg = GenerationConfig(coacd_threshold=0.3, max_visual_faces=1000, max_collision_pieces=4)
    asset = to_object_asset(obj, "cabinet_1", "cabinet", config=cfg)
    assert asset.kind is AssetKind.ARTICULATED
    door = next(p for p in asset.parts if p.name == "cabinet_door")
    assert door.parent == "cabinet_frame" and door.joint.type is JointType.REVOLUTE
    # mass from the meshes agrees with density x voxel volume (marching cubes at level 0.5)
    assert asset.mass_kg == pytest.approx(obj.voxel_mass_kg, rel=0.15)
    # per part within 25%: the one-voxel-thick door loses about a fifth of its volume in the
    # generator's smoothed marching cubes (measured: 9.9 kg from the mesh, 12.6 kg from voxels)
    for p in asset.parts:
        assert p.inertial.mass_kg == pytest.approx(700.0 * obj.part(p.name).volume_m3, rel=0.25)
    assert np.allclose(asset.size_m, [0.40, 1.00, 0.80], atol=0.02)


def test_qwen_image_processor_with_upstreams_pixel_bounds_gives_324_visual_tokens_for_512():
    from PIL import Image
    from transformers.models.qwen2_vl.image_processing_pil_qwen2_vl import Qwen2VLImageProcessorPil

    from generation.physx.vlm import UPSTREAM_IMAGE_PX, UPSTREAM_MAX_PIXELS, UPSTREAM_MIN_PIXELS

    assert (UPSTREAM_IMAGE_PX, UPSTREAM_MIN_PIXELS, UPSTREAM_MAX_PIXELS) == (512, 65536, 262144)
    proc = Qwen2VLImageProcessorPil(min_pixels=UPSTREAM_MIN_PIXELS, max_pixels=UPSTREAM_MAX_PIXELS)
    out = proc(images=[Image.new("RGB", (512, 512))], return_tensors="pt")
    assert out["image_grid_thw"].tolist() == [[1, 36, 36]]  # 504 x 504 pixels, 36 x 36 patches
    assert int(out["image_grid_thw"][0].prod()) // 4 == 324


def test_scale_is_reconciled_with_the_observed_box_on_all_three_axes():
    conv = run_conversation(CannedCabinet(), np.zeros((8, 8, 3), np.uint8), _prompts())
    own, _ = physx_from_conversation(conv)
    target = np.array([0.5, 1.2, 0.7])  # the model says 0.40 x 1.00 x 0.80 m
    obj, report = physx_from_conversation(conv, target_size_m=target)
    np.testing.assert_allclose(obj.size_m, target, rtol=1e-9)
    np.testing.assert_allclose(obj.scale_to_target, target / own.size_m, rtol=1e-9)
    door_own, door = own.part("cabinet_door"), obj.part("cabinet_door")
    # every part scaled per axis: voxel sizes, origins and the hinge's anchor
    np.testing.assert_allclose(door.voxel_size_m, door_own.voxel_size_m * obj.scale_to_target, rtol=1e-9)
    np.testing.assert_allclose(door.joint.anchor_m, door_own.joint.anchor_m * obj.scale_to_target, atol=1e-9)
    assert door.joint.lower == door_own.joint.lower  # angles are not lengths
    assert door.voxel_count == door_own.voxel_count
    # a box whose proportions are not the model's object's at all: refused (the caller falls back)
    with pytest.raises(ProtocolError, match="differ by more than 3x"):
        physx_from_conversation(conv, target_size_m=np.array([0.4, 0.15, 0.8]))
