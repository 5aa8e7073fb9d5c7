"""Tactile-to-language evidence (the paper's V-T-L row): a text adapter maps tactile features
into a text-embedding space, and forced choices between opposite words ask whether generated
touch carries what real touch carries, against generated touch with its rows shuffled.

Captions are written from each sample's ground truth with templates (`caption_for`): hard /
soft (the contact-compliance class), heavy / light (mass above / below the train rows' median)
and grippy / slippery (friction above / below the train median: the simulator's surfaces have
friction, not a rough or smooth texture under the gel, so this pair stands in for the paper's
rough / smooth).

The text encoder runs offline and is fitted inside the workflow (`TextEncoder`): TF-IDF over
the train captions' words, l2-normalised (scikit-learn), one dimension per word. A truncated
SVD on top was tried and dropped: templated captions give tied singular values, so the kept
subspace (and the forced choices) moved with the rounding of the solver. The
paper's frozen Qwen2.5-VL stage cannot run here (no weights can be downloaded); a pretrained
sentence encoder shipped on PyPI would need its weights from the network too. An encoder
fitted on the captions knows only their words, which is all a forced choice between two of
them needs.

The adapter (`fit_adapter`) is multi-output ridge regression from real tactile features to the
train captions' embeddings, its penalty by leave-one-out on the train rows. On the test rows a
forced choice picks, per attribute, the word whose embedding is nearer (cosine) to the
adapted tactile vector (`forced_choice`). The same adapter reads real touch, generated touch
and generated touch with its rows re-paired by a Sattolo cycle; the margin generated −
shuffled, with a paired fixed-test bootstrap CI, is the paper's evidence (+0.190 hard/soft,
+0.083 rough/smooth there).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from tacgen_lib.corpus.derangement import sattolo_cycle
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap, resample_indices, score_interval
from tacgen_lib.probes.rows import baseline_score

if TYPE_CHECKING:  # scikit-learn is imported where the encoder and adapter are fitted: the
    # report's language table reads PAPER_MARGINS from here without paying for it
    from sklearn.feature_extraction.text import TfidfVectorizer
    from sklearn.linear_model import RidgeCV

__all__ = [
    "ATTRIBUTES",
    "PAPER_MARGINS",
    "TEMPLATES",
    "TextEncoder",
    "attribute_labels",
    "caption_for",
    "fit_adapter",
    "fit_text_encoder",
    "forced_choice",
    "language_evidence",
]

#: Forced-choice attributes: name -> (word when the property is high, word when low).
ATTRIBUTES: dict[str, tuple[str, str]] = {
    "hardness": ("hard", "soft"),
    "weight": ("heavy", "light"),
    "grip": ("grippy", "slippery"),
}

#: The paper's margins of generated over shuffled generated touch (Δ, CI low, CI high) per
#: attribute; its rough / smooth pair is our grip pair's counterpart. Weight has none.
PAPER_MARGINS: dict[str, tuple[float, float, float]] = {
    "hardness": (0.190, 0.115, 0.261),
    "grip": (0.083, 0.034, 0.133),
}

#: Caption templates (one per sample, chosen by its position in sorted sample_id order).
TEMPLATES = (
    "a {hardness} {weight} object that feels {grip}",
    "it feels {hardness} and {grip}, and it is {weight}",
    "{weight} and {hardness} to the touch with a {grip} surface",
)

#: The adapter's ridge penalties (leave-one-out picks one).
ADAPTER_ALPHAS = tuple(float(a) for a in np.logspace(-2, 4, 13))


#: The manifest column each attribute is read from.
ATTRIBUTE_SOURCES = {"hardness": "hardness", "weight": "mass", "grip": "friction"}


def attribute_labels(manifest: pd.DataFrame, train_ids: Sequence[str]) -> pd.DataFrame:
    """Per sample (index sample_id), the word of each attribute (`ATTRIBUTES`) the manifest
    can give: hardness from the ``hardness`` label; weight and grip from ``mass`` and
    ``friction`` against the medians of the `train_ids` rows (a test row never moves a
    threshold). An attribute whose column is absent or empty is left out (a real corpus
    records no friction); an attribute whose train rows all have one word is left out too (a
    forced choice needs both words in the captions).

    Raises ValueError naming the sample_id for a hardness other than hard / soft, and when no
    attribute is left.
    """
    m = manifest.set_index("sample_id")
    train = m.loc[list(train_ids)]
    out = pd.DataFrame(index=m.index)
    for name, col in ATTRIBUTE_SOURCES.items():
        if col not in m.columns or m[col].isna().all():
            continue
        hi, lo = ATTRIBUTES[name]
        if name == "hardness":
            words = m[col].astype(str)
            unknown = ~words.isin([hi, lo])
            if unknown.any():
                raise ValueError(
                    f"captions: sample_id {m.index[unknown][0]!r} has hardness "
                    f"{words[unknown].iloc[0]!r} (need {hi!r} or {lo!r})"
                )
        else:
            values = pd.to_numeric(m[col], errors="coerce")
            if values.isna().any():
                raise ValueError(
                    f"captions: sample_id {m.index[values.isna()][0]!r} has no {col!r}"
                )
            words = pd.Series(
                np.where(values.to_numpy(float) > float(values.loc[train.index].median()), hi, lo),
                index=m.index,
            )
        if words.loc[train.index].nunique() < 2:
            continue
        out[name] = words
    if out.shape[1] == 0:
        raise ValueError(
            "captions: no attribute has both of its words among the train rows "
            f"(attributes {list(ATTRIBUTES)}, read from {list(ATTRIBUTE_SOURCES.values())})"
        )
    return out


def caption_for(words: Mapping[str, str], index: int) -> str:
    """The caption of a sample with these attribute words, template `index` mod the count
    (an attribute left out reads "unknown")."""
    filled = {name: words.get(name, "unknown") for name in ATTRIBUTES}
    return TEMPLATES[int(index) % len(TEMPLATES)].format(**filled)


@dataclass(frozen=True)
class TextEncoder:
    """TF-IDF over the caption words, l2-normalised: `encode` maps texts to unit vectors with
    one dimension per word of the train captions."""

    tfidf: TfidfVectorizer

    @property
    def dim(self) -> int:
        return len(self.tfidf.vocabulary_)

    def encode(self, texts: Sequence[str]) -> np.ndarray:
        return self.tfidf.transform(list(texts)).toarray()


def fit_text_encoder(captions: Sequence[str]) -> TextEncoder:
    """Fit the encoder on the train captions. Raises ValueError when they hold fewer than two
    distinct words."""
    from sklearn.feature_extraction.text import TfidfVectorizer

    tfidf = TfidfVectorizer(token_pattern=r"[a-z]+").fit(list(captions))
    vocab = len(tfidf.vocabulary_)
    if vocab < 2:
        raise ValueError(f"text encoder: the captions hold {vocab} distinct word(s); need >= 2")
    return TextEncoder(tfidf)


def fit_adapter(t_train: np.ndarray, e_train: np.ndarray) -> RidgeCV:
    """Ridge from tactile features (n, d_t) to caption embeddings (n, k), penalty by
    leave-one-out (one for all outputs)."""
    from sklearn.linear_model import RidgeCV

    return RidgeCV(alphas=list(ADAPTER_ALPHAS)).fit(
        np.asarray(t_train, np.float64), np.asarray(e_train, np.float64)
    )


def forced_choice(
    adapter: RidgeCV,
    encoder: TextEncoder,
    tactile: np.ndarray,
    attributes: Sequence[str] = tuple(ATTRIBUTES),
) -> dict[str, np.ndarray]:
    """Attribute -> the word chosen for each row: the one of its pair whose embedding has the
    higher cosine with the adapted tactile vector (ties to the first word)."""
    z = adapter.predict(np.asarray(tactile, np.float64))
    norm = np.linalg.norm(z, axis=1, keepdims=True)
    z = z / np.where(norm > 0, norm, 1.0)
    out = {}
    for name in attributes:
        hi, lo = ATTRIBUTES[name]
        words = encoder.encode([hi, lo])
        cos = z @ words.T
        out[name] = np.where(cos[:, 0] >= cos[:, 1], hi, lo).astype(object)
    return out


#: Columns of the language evidence edge (one row per attribute x tactile input).
EVIDENCE_COLUMNS = (
    "row_id",
    "corpus",
    "attribute",
    "input",
    "accuracy",
    "ci_low",
    "ci_high",
    "margin_vs_shuffled",
    "ci_low_vs_shuffled",
    "ci_high_vs_shuffled",
    "majority",
    "n_train",
    "n_test",
    "adapter_alpha",
    "text_dim",
)

#: The tactile inputs the adapter reads on the test rows.
INPUTS = ("real", "generated", "shuffled_generated")


def language_evidence(
    manifest: pd.DataFrame,
    train_ids: Sequence[str],
    test_ids: Sequence[str],
    t_real: Mapping[str, np.ndarray],
    t_gen: Mapping[str, np.ndarray],
    *,
    corpus: str,
    bootstrap: int,
    seed: int,
) -> pd.DataFrame:
    """Captions, encoder and adapter from the train rows; forced-choice accuracy of real,
    generated and shuffled generated touch on the test rows (`EVIDENCE_COLUMNS`).

    Shuffled generated: test row i reads the generated vector of test row perm[i], perm a
    seeded Sattolo cycle (no row keeps its own). Every accuracy has a fixed-test bootstrap CI;
    the margin against shuffled is paired on the same resamples.
    """
    train_ids, test_ids = [str(i) for i in train_ids], [str(i) for i in test_ids]
    if len(test_ids) < 2:
        raise ValueError(f"language evidence, corpus {corpus!r}: need >= 2 test rows")
    words = attribute_labels(manifest, train_ids)
    captions = [caption_for(words.loc[i], k) for k, i in enumerate(train_ids)]
    encoder = fit_text_encoder(captions)
    adapter = fit_adapter(np.stack([t_real[i] for i in train_ids]), encoder.encode(captions))
    perm = sattolo_cycle(len(test_ids), np.random.default_rng([int(seed), 0x6C616E67]))
    gen = np.stack([t_gen[i] for i in test_ids])
    tactile = {
        "real": np.stack([t_real[i] for i in test_ids]),
        "generated": gen,
        "shuffled_generated": gen[perm],
    }
    attrs = list(words.columns)
    chosen = {k: forced_choice(adapter, encoder, v, attrs) for k, v in tactile.items()}
    idx = resample_indices(len(test_ids), int(bootstrap), int(seed))
    rows = []
    for attr in attrs:
        y = words.loc[test_ids, attr].to_numpy(dtype=object)
        # the test accuracy of always choosing the train rows' commoner word
        majority = baseline_score(words.loc[train_ids, attr].to_numpy(dtype=object), y, "accuracy")
        shuffled = chosen["shuffled_generated"][attr]
        for inp in INPUTS:
            pred = chosen[inp][attr]
            lo, hi = score_interval("accuracy", y, pred, idx)
            vs = fixed_test_bootstrap(
                y, shuffled, pred, "accuracy", int(bootstrap), int(seed), indices=idx
            )
            rows.append(
                {
                    "row_id": f"{corpus}|{attr}|{inp}",
                    "corpus": corpus,
                    "attribute": attr,
                    "input": inp,
                    "accuracy": vs["vt_score"],
                    "ci_low": lo,
                    "ci_high": hi,
                    "margin_vs_shuffled": vs["delta"],
                    "ci_low_vs_shuffled": vs["ci_low"],
                    "ci_high_vs_shuffled": vs["ci_high"],
                    "majority": majority,
                    "n_train": len(train_ids),
                    "n_test": len(test_ids),
                    "adapter_alpha": float(adapter.alpha_),
                    "text_dim": encoder.dim,
                }
            )
    return pd.DataFrame(rows, columns=list(EVIDENCE_COLUMNS))
