"""Real-corpus ingest (tacgen_lib.corpus.ingest) on tiny copies of the TVL dataset in its
authors' layout (tests/fixtures_real.py): pairs selected as TVL's loaders select them, the
skipped ones counted, backgrounds found where TVL publishes them, tactile frames padded and
turned as TVL's code does, the edge streamed in row groups."""

from __future__ import annotations

import io
import shutil
import tracemalloc
from collections import Counter
from pathlib import Path

import cv2
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fixtures_real import (
    RGB_SHAPE,
    TACTILE_SHAPE,
    write_hct_fixture,
    write_ssvtp_fixture,
)
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image, ImageOps

from tacgen_lib.corpus.captions import (
    OTHER_STRATUM,
    hardness_from_adjectives,
    parse_caption,
    top_pattern_strata,
)
from tacgen_lib.corpus.ingest import (
    ingest_hct,
    ingest_ssvtp,
    listed_rows,
    load_ingested,
    plan_declared,
    plan_hct,
    plan_ssvtp,
    write_ingested,
)
from tacgen_lib.corpus.ingest_files import SAMPLE_COLUMNS, SENSOR_COLUMNS, pad_and_rotate
from tacgen_lib.io import edges
from tacgen_lib.io.images import decode_png
from tacgen_lib.preprocess.frames import sensor_background_map, subtract_backgrounds
from tacgen_lib.report.figures import corpus_example_grid


def imread_rgb(path: Path) -> np.ndarray:
    """Reference decode of a fixture image: OpenCV's own reader, BGR -> RGB."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert bgr is not None, path
    return bgr[:, :, ::-1]


def tvl_view(image: np.ndarray) -> np.ndarray:
    """Reference of TVL's tac_padding on a PIL image, as its loaders apply it: torchvision's
    pad on PIL (ImageOps.expand by (max side - side) // 2 on each side, black) and rotate(90)
    (PIL, counter-clockwise)."""
    h, w = image.shape[:2]
    side = max(h, w)
    hpad, wpad = (side - h) // 2, (side - w) // 2
    padded = ImageOps.expand(Image.fromarray(image), border=(wpad, hpad, wpad, hpad), fill=0)
    return np.asarray(padded.rotate(90))


def assert_names(err: pytest.ExceptionInfo, *parts: object) -> None:
    message = str(err.value)
    for part in parts:
        assert str(part) in message, f"{part!r} not in error message: {message}"


@pytest.fixture
def code(tmp_path: Path) -> Path:
    """A stand-in for a clone of the TVL code (it holds tvl_enc/data/tac_background.png)."""
    return tmp_path / "tvl-code"


@pytest.fixture
def ssvtp_root(tmp_path: Path, code: Path) -> Path:
    return write_ssvtp_fixture(tmp_path / "tvl", n=12, seed=0, code=code)


def assert_refused(root: Path, code: Path, error: type[Exception], *parts, match=None) -> None:
    """`ingest_ssvtp(root, background=code)` raises `error` (matching `match`), naming `parts`."""
    with pytest.raises(error, match=match) as err:
        ingest_ssvtp(root, background=code)
    assert_names(err, *parts)


@pytest.fixture
def hct_root(tmp_path: Path) -> Path:
    return write_hct_fixture(tmp_path / "tvl", n_traj=3, per_traj=4, seed=0)


# --------------------------------------------------------------------------- captions


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("smooth, hard, glossy", ["smooth", "hard", "glossy"]),
        ("  smooth ,   hard  ", ["smooth", "hard"]),  # extra spaces
        ("Smooth, HARD, Glossy", ["smooth", "hard", "glossy"]),  # capitals
        ("smooth, hard,", ["smooth", "hard"]),  # trailing comma
        ("smooth,, ,hard, , ", ["smooth", "hard"]),  # empty pieces
        ("smooth, hard, Smooth, hard.", ["smooth", "hard"]),  # duplicates keep first position
        ("soft, smooth.\n", ["soft", "smooth"]),  # TVL-style trailing period and newline
        ("slightly   rough, soft", ["slightly rough", "soft"]),  # inner spaces collapse
        ("hard\nsoft", ["hard", "soft"]),  # one adjective per line
        ("", []),
        (" , . ,", []),
    ],
)
def test_parse_caption_normalises(text: str, expected: list[str]) -> None:
    assert parse_caption(text) == expected


@pytest.mark.parametrize(
    ("adjs", "expected"),
    [
        (["smooth", "hard"], "hard"),
        (["soft", "fuzzy"], "soft"),
        (["hard", "soft"], None),  # both: contradictory caption, no label
        (["smooth", "glossy"], None),  # neither
        ([], None),
        (["Hard "], "hard"),  # normalised before matching
        (["hardened", "softish"], None),  # exact adjective match only
    ],
)
def test_hardness_from_adjectives(adjs: list[str], expected: str | None) -> None:
    assert hardness_from_adjectives(adjs) == expected


def test_top_pattern_strata_hand_example() -> None:
    lists = [
        ["soft", "smooth"],  # pattern smooth+soft (x3)
        ["smooth", "soft"],
        ["smooth", "soft"],
        ["hard"],  # hard (x2)
        ["hard"],
        ["rough"],  # rough (x2) ties with hard; hard wins by name
        ["rough"],
        ["glossy"],  # x1
    ]
    assert top_pattern_strata(lists, k=2) == [
        "smooth+soft",
        "smooth+soft",
        "smooth+soft",
        "hard",
        "hard",
        OTHER_STRATUM,
        OTHER_STRATUM,
        OTHER_STRATUM,
    ]
    assert top_pattern_strata(lists, k=0) == [OTHER_STRATUM] * len(lists)
    assert top_pattern_strata(lists, k=10)[-1] == "glossy"


def test_top_pattern_strata_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="position 1 is empty"):
        top_pattern_strata([["hard"], []])
    with pytest.raises(ValueError, match="k must be >= 0"):
        top_pattern_strata([["hard"]], k=-1)
    with pytest.raises(TypeError, match="is a string"):
        top_pattern_strata(["hard, soft"])


adjective_lists = st.lists(
    st.lists(st.sampled_from(["a", "b", "c", "d", "e"]), min_size=1, max_size=3),
    min_size=1,
    max_size=40,
)


@settings(max_examples=60, deadline=None)
@given(lists=adjective_lists, k=st.integers(0, 6), seed=st.integers(0, 2**32 - 1))
def test_top_pattern_strata_matches_reference_and_ignores_order(
    lists: list[list[str]], k: int, seed: int
) -> None:
    patterns = ["+".join(sorted(set(a))) for a in lists]
    counts = Counter(patterns)
    # reference: a pattern keeps its name iff fewer than k patterns beat it on count, then name
    kept = {
        p
        for p in counts
        if sum(counts[q] > counts[p] or (counts[q] == counts[p] and q < p) for q in counts) < k
    }
    expected = [p if p in kept else OTHER_STRATUM for p in patterns]
    assert top_pattern_strata(lists, k=k) == expected
    order = np.random.default_rng(seed).permutation(len(lists))
    shuffled = top_pattern_strata([lists[i] for i in order], k=k)
    assert shuffled == [expected[i] for i in order]


# --------------------------------------------------------------------------- TVL's tactile view


@pytest.mark.parametrize("shape", [TACTILE_SHAPE, TACTILE_SHAPE[::-1], (30, 30), (8, 12)])
def test_pad_and_rotate_is_tvl_tac_padding(shape):
    image = np.random.default_rng(0).integers(0, 256, size=(*shape, 3), dtype=np.uint8)
    got = pad_and_rotate(image)
    side = max(shape)
    assert got.shape == (side, side, 3)
    np.testing.assert_array_equal(got, tvl_view(image))


# --------------------------------------------------------------------------- SSVTP


def test_ssvtp_round_trip(ssvtp_root: Path, code: Path) -> None:
    samples, sensors = ingest_ssvtp(ssvtp_root, background=code)
    folder = ssvtp_root / "ssvtp"
    assert list(samples.columns) == list(SAMPLE_COLUMNS)
    assert list(sensors.columns) == list(SENSOR_COLUMNS)
    # the 12 listed pairs with their files; pairs 12 (unlisted), 13 and 14 (files missing) not
    assert samples["sample_id"].tolist() == [f"ssvtp-{i:06d}" for i in range(12)]
    assert set(samples["corpus"]) == {"ssvtp"}
    assert set(samples["sensor_id"]) == {"ssvtp-bg"}
    for i, row in samples.iterrows():
        rgb_path = folder / "images_rgb" / f"image_{i}_rgb.jpg"
        tac_path = folder / "images_tac" / f"image_{i}_tac.jpg"
        assert row["rgb"][:8] == b"\x89PNG\r\n\x1a\n"
        np.testing.assert_array_equal(decode_png(row["rgb"]), imread_rgb(rgb_path))
        assert decode_png(row["rgb"]).shape == (*RGB_SHAPE, 3)  # camera frames as stored
        np.testing.assert_array_equal(decode_png(row["tactile"]), tvl_view(imread_rgb(tac_path)))
        caption = (folder / "text" / f"labels_{i}.txt").read_text().strip()
        assert row["caption"] == caption
        assert row["adjectives"] == parse_caption(caption)
        assert row["hardness"] == hardness_from_adjectives(row["adjectives"])
        assert row["source_split"] == ("test" if i % 4 == 3 else "train")
        assert row["source_path"] == f"ssvtp/images_tac/image_{i}_tac.jpg"
    assert samples["stratum"].tolist() == top_pattern_strata(samples["adjectives"].tolist())
    assert sensors["sensor_id"].tolist() == ["ssvtp-bg"]
    background = imread_rgb(code / "tvl_enc" / "data" / "tac_background.png")
    assert background.shape[:2] == TACTILE_SHAPE
    np.testing.assert_array_equal(decode_png(sensors["background"].iloc[0]), tvl_view(background))


def test_ssvtp_plan_counts_the_pairs_it_leaves_out(ssvtp_root: Path, code: Path) -> None:
    plan = plan_ssvtp(ssvtp_root, background=code)
    unlisted, missing = plan.skipped.values()
    assert unlisted == ["ssvtp-000012"]
    assert missing == [
        "ssvtp-000013 (images_rgb/image_13_rgb.jpg, images_tac/image_13_tac.jpg, "
        "text/labels_13.txt)",
        "ssvtp-000014 (images_tac/image_14_tac.jpg)",
    ]
    report = "\n".join(plan.report())
    assert "skipped 1 pairs listed in neither train.csv nor test.csv: ssvtp-000012" in report
    assert "skipped 2 listed pairs with missing files: ssvtp-000013" in report
    assert listed_rows("ssvtp", str(ssvtp_root)) == 14  # what the CSVs list: 12 + 2 missing


def test_ssvtp_parquet_round_trip(ssvtp_root: Path, code: Path) -> None:
    """The tables survive Parquet (the edge format): bytes, lists and nulls come back as is."""
    samples, sensors = ingest_ssvtp(ssvtp_root, background=code)
    for table in (samples, sensors):
        back = pq.read_table(io.BytesIO(parquet_bytes(table))).to_pylist()
        assert back == table.to_dict(orient="records")
    schema = pq.read_table(io.BytesIO(parquet_bytes(samples))).schema
    assert str(schema.field("rgb").type) == "binary"
    assert str(schema.field("adjectives").type) == "list<element: string>"
    assert str(schema.field("hardness").type) == "string"


def test_ssvtp_background_where_tvl_publishes_it_or_a_copy(ssvtp_root, code, tmp_path):
    file = code / "tvl_enc" / "data" / "tac_background.png"
    by_code = ingest_ssvtp(ssvtp_root, corpus="tvl-ssvtp", background=code)
    by_file = ingest_ssvtp(ssvtp_root, corpus="tvl-ssvtp", background=file)
    assert by_code[0]["sample_id"].iloc[0] == "tvl-ssvtp-000000"
    assert by_code[1]["sensor_id"].tolist() == ["tvl-ssvtp-bg"]
    assert by_code[1].equals(by_file[1])
    # the config key reaches it (corpora.<name>.background)
    plan = plan_declared(ssvtp_root, {"name": "s", "kind": "ssvtp", "background": str(code)})
    assert plan.backgrounds == {"s-bg": file}
    # unset: a copy next to the data
    shutil.copy(file, ssvtp_root / "ssvtp" / "tac_background.png")
    copied = ingest_ssvtp(ssvtp_root)[1]
    assert copied["background"].tolist() == by_file[1]["background"].tolist()


def test_ssvtp_background_missing_says_where_to_get_it(ssvtp_root: Path, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as err:
        ingest_ssvtp(ssvtp_root)
    assert_names(
        err,
        ssvtp_root / "ssvtp" / "tac_background.png",
        "github.com/Max-Fu/tvl",
        "tvl_enc/data/tac_background.png",
        "corpora.<name>.background",
        "ssvtp-bg",
    )
    with pytest.raises(FileNotFoundError) as err:
        ingest_ssvtp(ssvtp_root, background=tmp_path / "elsewhere")  # a folder: a code clone?
    assert_names(err, tmp_path / "elsewhere" / "tvl_enc" / "data" / "tac_background.png")


def test_ssvtp_without_split_csvs_takes_every_rgb_file(ssvtp_root: Path, code: Path) -> None:
    (ssvtp_root / "ssvtp" / "train.csv").unlink()
    (ssvtp_root / "ssvtp" / "test.csv").unlink()
    plan = plan_ssvtp(ssvtp_root, background=code)
    # as TVL's loader lists images_rgb/: pairs 0-12; pair 14 lacks its tactile frame
    assert [s.sample_id for s in plan.samples] == [f"ssvtp-{i:06d}" for i in range(13)]
    assert [s.source_split for s in plan.samples] == [None] * 13
    assert plan.skipped == {
        "listed pairs with missing files": ["ssvtp-000014 (images_tac/image_14_tac.jpg)"]
    }


def test_ssvtp_csv_without_header_and_unlisted_pairs(ssvtp_root: Path, code: Path) -> None:
    folder = ssvtp_root / "ssvtp"
    (folder / "train.csv").write_text("images_rgb/image_0_rgb.jpg\nimages_rgb/image_1_rgb.jpg\n")
    plan = plan_ssvtp(ssvtp_root, background=code)
    split = {s.sample_id: s.source_split for s in plan.samples}
    assert split == {"ssvtp-000000": "train", "ssvtp-000001": "train"} | {
        f"ssvtp-{i:06d}": "test" for i in (3, 7, 11)
    }
    # on disk: the RGB files of pairs 0-12 and 14; listed: 5 of them
    assert len(plan.skipped["pairs listed in neither train.csv nor test.csv"]) == 14 - 5


@pytest.mark.parametrize(
    ("missing", "named"),
    [
        ("images_rgb/image_3_rgb.jpg", "ssvtp-000003 (images_rgb/image_3_rgb.jpg)"),
        ("images_tac/image_5_tac.jpg", "ssvtp-000005 (images_tac/image_5_tac.jpg)"),
        ("text/labels_7.txt", "ssvtp-000007 (text/labels_7.txt)"),
    ],
)
def test_ssvtp_listed_pair_with_a_missing_file_is_skipped_and_reported(
    ssvtp_root: Path, code: Path, missing: str, named: str
) -> None:
    (ssvtp_root / "ssvtp" / missing).unlink()
    plan = plan_ssvtp(ssvtp_root, background=code)
    assert len(plan.samples) == 11
    assert named in plan.skipped["listed pairs with missing files"]


@pytest.mark.parametrize("content", [b"not a jpeg at all", b""])
def test_ssvtp_unreadable_image(ssvtp_root: Path, code: Path, content: bytes) -> None:
    path = ssvtp_root / "ssvtp" / "images_rgb" / "image_2_rgb.jpg"
    path.write_bytes(content)
    assert_refused(ssvtp_root, code, ValueError, path, "ssvtp-000002", match="not a readable image")


@pytest.mark.parametrize("caption", ["", "  \n", " , ,. ,"])
def test_ssvtp_empty_caption(ssvtp_root: Path, code: Path, caption: str) -> None:
    path = ssvtp_root / "ssvtp" / "text" / "labels_4.txt"
    path.write_text(caption)
    assert_refused(ssvtp_root, code, ValueError, path, "ssvtp-000004", match="empty caption")


def test_ssvtp_frame_and_background_sizes_differ(ssvtp_root: Path, code: Path) -> None:
    bg = code / "tvl_enc" / "data" / "tac_background.png"
    h, w = TACTILE_SHAPE
    tac = ssvtp_root / "ssvtp" / "images_tac" / "image_0_tac.jpg"
    # any other size: both sizes named
    cv2.imwrite(str(bg), np.zeros((10, 10, 3), np.uint8))
    assert_refused(ssvtp_root, code, ValueError, bg, tac, f"{h} x {w}", "10 x 10", "ssvtp-000000")
    # the background turned a quarter: the orientation named
    cv2.imwrite(str(bg), np.zeros((w, h, 3), np.uint8))
    assert_refused(ssvtp_root, code, ValueError, f"{w} x {h}", match="turned a quarter")
    # tactile and vision files swapped, as in TVL's first release: the revised release named
    cv2.imwrite(str(bg), np.zeros((*RGB_SHAPE, 3), np.uint8))
    assert_refused(ssvtp_root, code, ValueError, "TVL-revise", match="look swapped")


def test_ssvtp_csv_row_naming_another_file_names_csv_and_line(ssvtp_root, code) -> None:
    path = ssvtp_root / "ssvtp" / "train.csv"
    (ssvtp_root / "ssvtp" / "images_rgb" / "picture.jpg").write_bytes(b"x")
    with path.open("a") as handle:
        handle.write("images_rgb/picture.jpg,,\n")
    n_lines = len(path.read_text().splitlines())
    assert_refused(
        ssvtp_root, code, ValueError, path, f"line {n_lines}", match="not an SSVTP RGB path"
    )


def test_ssvtp_pair_in_both_splits(ssvtp_root: Path, code: Path) -> None:
    path = ssvtp_root / "ssvtp" / "test.csv"
    with path.open("a") as handle:
        handle.write("images_rgb/image_0_rgb.jpg,images_tac/image_0_tac.jpg,hard\n")
    assert_refused(ssvtp_root, code, ValueError, "ssvtp-000000", "train.csv", path, match="both")


def test_ssvtp_wrong_root(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as err:
        ingest_ssvtp(tmp_path)
    assert_names(err, tmp_path / "ssvtp")


# --------------------------------------------------------------------------- HCT


def test_hct_round_trip(hct_root: Path) -> None:
    samples, sensors = ingest_hct(hct_root)
    hct = hct_root / "hct"
    assert list(samples.columns) == list(SAMPLE_COLUMNS)
    assert list(sensors.columns) == list(SENSOR_COLUMNS)
    # data{1,2,3} each hold one trajectory: 3 train rows, then 1 test row
    assert samples["sample_id"].tolist() == [
        f"hct-data{d}-{r:05d}" for d in (1, 2, 3) for r in range(4)
    ]
    assert samples["source_split"].tolist() == (["train"] * 3 + ["test"]) * 3
    # trajectory 1 (data2) has no background of its own: TVL's fallback, three levels up
    assert sensors["sensor_id"].tolist() == [
        "hct-bg:data1/0-1702507215.615537/background.png",
        "hct-bg:data3/2-1702507338.115537/background.png",
        "hct-bg:digit_background.png",
    ]
    assert set(samples.loc[4:7, "sensor_id"]) == {"hct-bg:digit_background.png"}
    background_of = dict(zip(sensors["sensor_id"], sensors["background"], strict=True))
    for _, row in samples.iterrows():
        tac_path = hct_root / row["source_path"]
        trajectory = tac_path.parent.parent
        bg = hct / row["sensor_id"].removeprefix("hct-bg:")
        assert bg.is_file() and tac_path.parent.name == "tactile"
        np.testing.assert_array_equal(decode_png(row["tactile"]), tvl_view(imread_rgb(tac_path)))
        rgb_path = trajectory / "vision" / tac_path.name
        np.testing.assert_array_equal(decode_png(row["rgb"]), imread_rgb(rgb_path))
        np.testing.assert_array_equal(
            decode_png(background_of[row["sensor_id"]]), tvl_view(imread_rgb(bg))
        )
        assert row["adjectives"] == parse_caption(row["caption"])
    assert samples["stratum"].tolist() == top_pattern_strata(samples["adjectives"].tolist())
    assert listed_rows("hct", str(hct_root)) == 12  # not_contact.json's frames are not rows


def rewrite_header(csv_path: Path, header: list[str], order: list[int] | None = None) -> None:
    frame = pd.read_csv(csv_path, keep_default_na=False)
    if order is not None:
        frame = frame.iloc[:, order]
    frame.columns = header
    frame.to_csv(csv_path, index=False)


def test_hct_columns_by_the_authors_names_in_any_order_or_by_position(hct_root: Path) -> None:
    reference, _ = ingest_hct(hct_root)
    train = hct_root / "hct" / "data1" / "train.csv"
    rewrite_header(train, ["caption", "tactile_background", "url", "tactile"], [3, 2, 0, 1])
    assert ingest_hct(hct_root)[0].equals(reference)  # PretrainDataset reads them by name
    rewrite_header(train, ["Vision", " tactile", "background", "caption"], [2, 3, 1, 0])
    assert ingest_hct(hct_root)[0].equals(reference)  # the names TacVisDatasetV2 gives them
    rewrite_header(train, ["a", "b", "c", "d"])
    plan = plan_hct(hct_root)
    assert "read by position" in plan.notes[0] and str(train) in plan.notes[0]
    assert load_ingested(plan)[0].equals(reference)  # TacVisDatasetV2 reads them by position


def test_hct_csv_missing_column(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    frame = pd.read_csv(path).drop(columns=["tactile_background"])
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match="missing column 'tactile_background'") as err:
        ingest_hct(hct_root)
    assert_names(err, path)


def test_hct_row_without_background_is_ingested_and_refused_by_subtraction(hct_root: Path):
    hct = hct_root / "hct"
    (hct / "data1" / "0-1702507215.615537" / "background.png").unlink()
    plan = plan_hct(hct_root)
    # TVL's fallback three levels up is hct/digit_background.png: trajectory 0 takes it now
    assert {s.sensor_id for s in plan.samples[:4]} == {"hct-bg:digit_background.png"}
    (hct / "digit_background.png").unlink()
    plan = plan_hct(hct_root)
    lacking = [f"hct-data{d}-{r:05d}" for d in (1, 2) for r in range(4)]
    assert plan.without_background == lacking
    assert "8 samples have no tactile background" in "\n".join(plan.report())
    samples, sensors = load_ingested(plan)
    assert len(samples) == 12 and len(sensors) == 1
    where = "rule background_subtract, results/corpus/hct/samples.parquet"
    with pytest.raises(ValueError) as err:
        subtract_backgrounds(samples, sensor_background_map(sensors), "clip128", where=where)
    assert_names(err, where, "8 of 12 samples", *lacking, "hct-bg:data1/0-1702507215.615537")
    # the report's example grid still draws them, with blank background panels
    splits = pd.DataFrame({"sample_id": samples["sample_id"], "split": "train"})
    figure = corpus_example_grid(samples, sensors, splits, n=12, title="hct")
    assert len([ax for ax in figure.axes if ax.images]) == 12 * 4
    plt.close(figure)


def test_hct_empty_caption(hct_root: Path) -> None:
    path = hct_root / "hct" / "data1" / "test.csv"
    frame = pd.read_csv(path, keep_default_na=False)
    frame.loc[0, "caption"] = " ,  "
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match="empty caption") as err:
        ingest_hct(hct_root)
    # data1 has 3 train rows, so its first test row is row 3; CSV line 2 (after the header)
    assert_names(err, f"{path}:2", "hct-data1-00003")


def test_hct_missing_tactile(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    image = hct_root / "hct" / "data2" / pd.read_csv(path)["tactile"].iloc[2]
    image.unlink()
    with pytest.raises(FileNotFoundError) as err:
        ingest_hct(hct_root)
    assert_names(err, image, f"{path}:4", "hct-data2-00002", "tactile")


def test_hct_unreadable_rgb(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    image = hct_root / "hct" / "data2" / pd.read_csv(path)["url"].iloc[0]
    image.write_bytes(b"\xff\xd8\xff garbage")
    with pytest.raises(ValueError, match="not a readable image") as err:
        ingest_hct(hct_root)
    assert_names(err, image, "hct-data2-00000", "RGB")


def test_hct_data_folder_without_csvs(hct_root: Path) -> None:
    (hct_root / "hct" / "data2" / "train.csv").unlink()
    (hct_root / "hct" / "data2" / "test.csv").unlink()
    with pytest.raises(FileNotFoundError, match="contact.json") as err:
        ingest_hct(hct_root)
    assert_names(err, hct_root / "hct" / "data2")


def test_hct_wrong_root(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as err:
        ingest_hct(tmp_path)
    assert_names(err, tmp_path / "hct")
    (tmp_path / "hct").mkdir()
    with pytest.raises(FileNotFoundError, match="no HCT data folders"):
        ingest_hct(tmp_path)


# --------------------------------------------------------------------------- streamed edges


def parquet_bytes(table: pd.DataFrame) -> bytes:
    buffer = io.BytesIO()
    pq.write_table(pa.Table.from_pandas(table, preserve_index=False), buffer)
    return buffer.getvalue()


def test_ingest_is_deterministic(tmp_path: Path) -> None:
    roots = [tmp_path / "a", tmp_path / "b"]
    for root in roots:
        write_ssvtp_fixture(root, n=6, seed=3)
        write_hct_fixture(root, n_traj=2, per_traj=3, seed=3)
    for name in ("ssvtp/images_tac/image_4_tac.jpg", "hct/data2/train.csv"):
        assert (roots[0] / name).read_bytes() == (roots[1] / name).read_bytes()
    for ingest in (ingest_ssvtp, ingest_hct):
        first, second = ingest(roots[0]), ingest(roots[1])
        for a, b in zip(first, second, strict=True):
            assert parquet_bytes(a) == parquet_bytes(b)


def test_streamed_edges_hold_the_tables_in_row_groups(hct_root: Path, tmp_path: Path) -> None:
    samples, sensors = ingest_hct(hct_root)
    plan = plan_hct(hct_root)
    out = [tmp_path / "one", tmp_path / "two"]
    for d in out:
        counts = write_ingested(plan, d / "s.parquet", d / "b.parquet", group_bytes=500_000)
        assert counts == (12, 3)
    # the same batches give the same bytes; several row groups
    for name in ("s.parquet", "b.parquet"):
        assert (out[0] / name).read_bytes() == (out[1] / name).read_bytes()
    assert pq.ParquetFile(out[0] / "s.parquet").num_row_groups > 1
    got = edges.read(out[0] / "s.parquet").frame
    for column in SAMPLE_COLUMNS:
        have = got[column].tolist()
        if column == "adjectives":
            have = [list(v) for v in have]
        elif column in ("hardness", "source_split"):  # nulls read back as NaN
            have = [v if isinstance(v, str) else None for v in have]
        assert have == samples[column].tolist(), column
    got = edges.read(out[0] / "b.parquet").frame
    assert got["background"].tolist() == sensors["background"].tolist()


def test_streamed_ingest_holds_one_row_group_however_many_samples_it_writes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The Python memory held (tracemalloc: images, PNG bytes, frames) as each row group of
    about one sample reaches the edge writer stays flat over the stream: held in memory, the
    samples would add a frame's PNG each."""
    root = write_hct_fixture(tmp_path / "tvl", n_traj=5, per_traj=4)
    plan = plan_hct(root)
    held: list[int] = []
    write_batches = edges.write_batches

    def watched(path, schema, batches, **kw):
        def groups():
            for group in batches:
                held.append(tracemalloc.get_traced_memory()[0])
                yield group

        return write_batches(path, schema, groups(), **kw)

    monkeypatch.setattr(edges, "write_batches", watched)
    tracemalloc.start()
    try:
        write_ingested(plan, tmp_path / "s.parquet", tmp_path / "b.parquet", group_bytes=1)
    finally:
        tracemalloc.stop()
    samples = held[len(plan.backgrounds) :]  # the sensors edge's groups come first
    assert len(samples) == 20
    frame_png = len(ingest_hct(root)[0]["tactile"].iloc[0])
    assert max(samples[4:]) - samples[3] < frame_png  # 16 more samples streamed: no growth
