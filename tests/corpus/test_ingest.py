"""Real-corpus ingest (tacgen_lib.corpus.ingest) on tiny copies of the TVL SSVTP and HCT layouts."""

from __future__ import annotations

import io
import shutil
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fixtures_real import IMAGE_SHAPE, write_hct_fixture, write_ssvtp_fixture
from hypothesis import given, settings
from hypothesis import strategies as st

from tacgen_lib.corpus.captions import (
    OTHER_STRATUM,
    hardness_from_adjectives,
    parse_caption,
    top_pattern_strata,
)
from tacgen_lib.corpus.ingest import ingest_hct, ingest_ssvtp
from tacgen_lib.corpus.ingest_files import SAMPLE_COLUMNS, SENSOR_COLUMNS
from tacgen_lib.io.images import decode_png


def imread_rgb(path: Path) -> np.ndarray:
    """Reference decode of a fixture image: OpenCV's own reader, BGR -> RGB."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert bgr is not None, path
    return bgr[:, :, ::-1]


def assert_names(err: pytest.ExceptionInfo, *parts: object) -> None:
    message = str(err.value)
    for part in parts:
        assert str(part) in message, f"{part!r} not in error message: {message}"


def assert_refused(root: Path, error: type[Exception], *parts: object, match=None) -> None:
    """`ingest_ssvtp(root)` raises `error` (matching `match`), its message naming `parts`."""
    with pytest.raises(error, match=match) as err:
        ingest_ssvtp(root)
    assert_names(err, *parts)


@pytest.fixture
def ssvtp_root(tmp_path: Path) -> Path:
    return write_ssvtp_fixture(tmp_path / "tvl", n=12, seed=0)


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


# --------------------------------------------------------------------------- SSVTP round trip


def test_ssvtp_round_trip(ssvtp_root: Path) -> None:
    samples, sensors = ingest_ssvtp(ssvtp_root)
    folder = ssvtp_root / "ssvtp"
    assert list(samples.columns) == list(SAMPLE_COLUMNS)
    assert list(sensors.columns) == list(SENSOR_COLUMNS)
    assert samples["sample_id"].tolist() == [f"ssvtp-{i:06d}" for i in range(12)]
    assert samples["sample_id"].is_unique
    assert set(samples["corpus"]) == {"ssvtp"}
    assert set(samples["sensor_id"]) == {"ssvtp-bg"}
    for i, row in samples.iterrows():
        rgb_path = folder / "images_rgb" / f"image_{i}_rgb.jpg"
        tac_path = folder / "images_tac" / f"image_{i}_tac.jpg"
        assert row["rgb"][:8] == b"\x89PNG\r\n\x1a\n"
        np.testing.assert_array_equal(decode_png(row["rgb"]), imread_rgb(rgb_path))
        np.testing.assert_array_equal(decode_png(row["tactile"]), imread_rgb(tac_path))
        caption = (folder / "text" / f"labels_{i}.txt").read_text().strip()
        assert row["caption"] == caption
        assert row["adjectives"] == parse_caption(caption)
        assert row["hardness"] == hardness_from_adjectives(row["adjectives"])
        assert row["source_split"] == ("test" if i % 4 == 3 else "train")
        assert row["source_path"] == f"ssvtp/images_tac/image_{i}_tac.jpg"
    assert samples["stratum"].tolist() == top_pattern_strata(samples["adjectives"].tolist())
    assert sensors["sensor_id"].tolist() == ["ssvtp-bg"]
    np.testing.assert_array_equal(
        decode_png(sensors["background"].iloc[0]), imread_rgb(folder / "tac_background.png")
    )
    assert decode_png(sensors["background"].iloc[0]).shape == (*IMAGE_SHAPE, 3)


def test_ssvtp_parquet_round_trip(ssvtp_root: Path) -> None:
    """The tables survive Parquet (the edge format): bytes, lists and nulls come back as is."""
    samples, sensors = ingest_ssvtp(ssvtp_root)
    for table in (samples, sensors):
        back = pq.read_table(io.BytesIO(parquet_bytes(table))).to_pylist()
        assert back == table.to_dict(orient="records")
    schema = pq.read_table(io.BytesIO(parquet_bytes(samples))).schema
    assert str(schema.field("rgb").type) == "binary"
    assert str(schema.field("adjectives").type) == "list<element: string>"
    assert str(schema.field("hardness").type) == "string"


def test_ssvtp_corpus_name_and_background_option(ssvtp_root: Path, tmp_path: Path) -> None:
    custom = tmp_path / "elsewhere" / "bg.png"
    custom.parent.mkdir()
    shutil.move(ssvtp_root / "ssvtp" / "tac_background.png", custom)
    samples, sensors = ingest_ssvtp(ssvtp_root, corpus="tvl-ssvtp", background=custom)
    assert samples["sample_id"].iloc[0] == "tvl-ssvtp-000000"
    assert set(samples["corpus"]) == {"tvl-ssvtp"}
    assert sensors["sensor_id"].tolist() == ["tvl-ssvtp-bg"]


def test_ssvtp_without_split_csvs_has_no_source_split(ssvtp_root: Path) -> None:
    (ssvtp_root / "ssvtp" / "train.csv").unlink()
    (ssvtp_root / "ssvtp" / "test.csv").unlink()
    samples, _ = ingest_ssvtp(ssvtp_root)
    assert len(samples) == 12
    assert samples["source_split"].tolist() == [None] * 12


def test_ssvtp_csv_without_header_and_unlisted_pairs(ssvtp_root: Path) -> None:
    folder = ssvtp_root / "ssvtp"
    (folder / "train.csv").write_text("images_rgb/image_0_rgb.jpg\nimages_rgb/image_1_rgb.jpg\n")
    samples, _ = ingest_ssvtp(ssvtp_root)
    split = dict(zip(samples["sample_id"], samples["source_split"], strict=True))
    assert split["ssvtp-000000"] == "train"
    assert split["ssvtp-000003"] == "test"
    assert split["ssvtp-000002"] is None  # listed in neither CSV: kept, without a source split


# --------------------------------------------------------------------------- HCT round trip


def test_hct_round_trip(hct_root: Path) -> None:
    samples, sensors = ingest_hct(hct_root)
    hct = hct_root / "hct"
    assert list(samples.columns) == list(SAMPLE_COLUMNS)
    assert list(sensors.columns) == list(SENSOR_COLUMNS)
    assert len(samples) == 12 and samples["sample_id"].is_unique
    assert samples["sample_id"].tolist() == sorted(samples["sample_id"])
    # data1 holds trajectories 0 and 2 (6 train rows, then 2 test rows); data2 holds trajectory 1
    assert samples["sample_id"].tolist() == [f"hct-data1-{r:05d}" for r in range(8)] + [
        f"hct-data2-{r:05d}" for r in range(4)
    ]
    assert samples["source_split"].tolist() == ["train"] * 6 + ["test"] * 2 + ["train"] * 3 + [
        "test"
    ]
    assert len(sensors) == 3 and sensors["sensor_id"].is_unique
    background_of = dict(zip(sensors["sensor_id"], sensors["background"], strict=True))
    for _, row in samples.iterrows():
        tac_path = hct_root / row["source_path"]
        trajectory = tac_path.parent.parent
        assert row["sensor_id"] == f"hct-bg:{trajectory.relative_to(hct).as_posix()}/background.png"
        np.testing.assert_array_equal(decode_png(row["tactile"]), imread_rgb(tac_path))
        rgb_path = trajectory / "vision" / tac_path.name
        np.testing.assert_array_equal(decode_png(row["rgb"]), imread_rgb(rgb_path))
        np.testing.assert_array_equal(
            decode_png(background_of[row["sensor_id"]]), imread_rgb(trajectory / "background.png")
        )
        assert row["adjectives"] == parse_caption(row["caption"])
        assert row["hardness"] == hardness_from_adjectives(row["adjectives"])
    assert samples["stratum"].tolist() == top_pattern_strata(samples["adjectives"].tolist())


def test_hct_falls_back_to_digit_background(hct_root: Path) -> None:
    data1 = hct_root / "hct" / "data1"
    trajectory = next(p for p in sorted(data1.iterdir()) if p.is_dir())
    shutil.move(trajectory / "background.png", data1 / "digit_background.png")
    samples, sensors = ingest_hct(hct_root)
    in_trajectory = samples["source_path"].str.contains(trajectory.name, regex=False)
    assert set(samples.loc[in_trajectory, "sensor_id"]) == {"hct-bg:data1/digit_background.png"}
    assert "hct-bg:data1/digit_background.png" in set(sensors["sensor_id"])


# --------------------------------------------------------------------------- determinism


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
        again = ingest(roots[0])
        for a, b in zip(first, again, strict=True):
            assert parquet_bytes(a) == parquet_bytes(b)


# --------------------------------------------------------------------------- SSVTP errors


@pytest.mark.parametrize(
    ("missing", "names"),
    [
        ("images_rgb/image_3_rgb.jpg", ("ssvtp-000003", "RGB")),
        ("images_tac/image_5_tac.jpg", ("ssvtp-000005", "tactile")),
        ("text/labels_7.txt", ("ssvtp-000007",)),
    ],
)
def test_ssvtp_missing_file_names_path_and_sample(
    ssvtp_root: Path, missing: str, names: tuple[str, ...]
) -> None:
    path = ssvtp_root / "ssvtp" / missing
    path.unlink()
    assert_refused(ssvtp_root, FileNotFoundError, path, *names)


@pytest.mark.parametrize("content", [b"not a jpeg at all", b""])
def test_ssvtp_unreadable_image(ssvtp_root: Path, content: bytes) -> None:
    path = ssvtp_root / "ssvtp" / "images_rgb" / "image_2_rgb.jpg"
    path.write_bytes(content)
    assert_refused(ssvtp_root, ValueError, path, "ssvtp-000002", match="not a readable image")


@pytest.mark.parametrize("caption", ["", "  \n", " , ,. ,"])
def test_ssvtp_empty_caption(ssvtp_root: Path, caption: str) -> None:
    path = ssvtp_root / "ssvtp" / "text" / "labels_4.txt"
    path.write_text(caption)
    assert_refused(ssvtp_root, ValueError, path, "ssvtp-000004", match="empty caption")


def test_ssvtp_background_missing(ssvtp_root: Path, tmp_path: Path) -> None:
    path = ssvtp_root / "ssvtp" / "tac_background.png"
    path.unlink()
    assert_refused(ssvtp_root, FileNotFoundError, path, "ssvtp-bg", "background=")
    other = tmp_path / "nope.png"
    with pytest.raises(FileNotFoundError) as err:
        ingest_ssvtp(ssvtp_root, background=other)
    assert_names(err, other)


def test_ssvtp_background_size_mismatch(ssvtp_root: Path) -> None:
    path = ssvtp_root / "ssvtp" / "tac_background.png"
    cv2.imwrite(str(path), np.zeros((10, 10, 3), np.uint8))
    assert_refused(
        ssvtp_root, ValueError, path, "ssvtp-000000", "image_0_tac.jpg", match="equal sizes"
    )


def test_ssvtp_bad_csv_row_names_csv_and_line(ssvtp_root: Path) -> None:
    path = ssvtp_root / "ssvtp" / "train.csv"
    with path.open("a") as handle:
        handle.write("images_rgb/picture.jpg\n")
    n_lines = len(path.read_text().splitlines())
    assert_refused(
        ssvtp_root,
        ValueError,
        path,
        f"line {n_lines}",
        "picture.jpg",
        match="not an SSVTP RGB path",
    )


def test_ssvtp_pair_in_both_splits(ssvtp_root: Path) -> None:
    path = ssvtp_root / "ssvtp" / "test.csv"
    with path.open("a") as handle:
        handle.write("images_rgb/image_0_rgb.jpg\n")
    assert_refused(ssvtp_root, ValueError, "ssvtp-000000", "train.csv", path, match="both")


def test_ssvtp_listed_but_absent_pair(ssvtp_root: Path) -> None:
    with (ssvtp_root / "ssvtp" / "train.csv").open("a") as handle:
        handle.write("images_rgb/image_40_rgb.jpg\n")
    assert_refused(
        ssvtp_root,
        FileNotFoundError,
        ssvtp_root / "ssvtp" / "images_rgb" / "image_40_rgb.jpg",
        "ssvtp-000040",
    )


def test_ssvtp_wrong_root(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as err:
        ingest_ssvtp(tmp_path)
    assert_names(err, tmp_path / "ssvtp")


# --------------------------------------------------------------------------- HCT errors


def test_hct_csv_missing_column(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    frame = pd.read_csv(path).drop(columns=["background"])
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match="missing column 'background'") as err:
        ingest_hct(hct_root)
    assert_names(err, path)


def test_hct_empty_caption(hct_root: Path) -> None:
    path = hct_root / "hct" / "data1" / "test.csv"
    frame = pd.read_csv(path, keep_default_na=False)
    frame.loc[1, "caption"] = " ,  "
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match="empty caption") as err:
        ingest_hct(hct_root)
    # data1 has 6 train rows, so the second test row is row 7; CSV line 3 (after the header)
    assert_names(err, f"{path}:3", "hct-data1-00007")


def test_hct_missing_tactile(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    relative = pd.read_csv(path)["tactile"].iloc[2]
    image = hct_root / "hct" / "data2" / relative
    image.unlink()
    with pytest.raises(FileNotFoundError) as err:
        ingest_hct(hct_root)
    assert_names(err, image, "hct-data2-00002", "tactile")


def test_hct_unreadable_rgb(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    image = hct_root / "hct" / "data2" / pd.read_csv(path)["vision"].iloc[0]
    image.write_bytes(b"\xff\xd8\xff garbage")
    with pytest.raises(ValueError, match="not a readable image") as err:
        ingest_hct(hct_root)
    assert_names(err, image, "hct-data2-00000", "RGB")


def test_hct_background_missing(hct_root: Path) -> None:
    path = hct_root / "hct" / "data2" / "train.csv"
    background = hct_root / "hct" / "data2" / pd.read_csv(path)["background"].iloc[0]
    background.unlink()
    with pytest.raises(FileNotFoundError) as err:
        ingest_hct(hct_root)
    assert_names(err, background, "hct-data2-00000", "digit_background.png")


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
