"""Behaviour cloning of one condition x H x E x seed cell on the demonstrations (rule train_policy)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import pandas as pd
import torch

from tacgen_lib.io import edges, hashed, log
from tacgen_lib.policy import bc, data
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.runtime.device import torch_device

logger = log.for_rule(snakemake)
torch.set_num_threads(snakemake.threads)
settings = PolicySettings.from_config(snakemake.params.settings)
w = snakemake.wildcards
hidden, epochs, seed = int(w.hidden), int(w.epochs), int(w.seed)
edge = edges.read(snakemake.input.palpation)
frame = edge.frame
train = (frame["split"] == "train").to_numpy()
# the guard: every row this rule fits on must be a demonstration (never a held-out episode)
mask = data.training_rows(frame, frame["episode_id"][train], rule=snakemake.rule)
vec = edge.vectors
null = bc.null_pairing(frame["episode_id"].to_numpy(), frame["split"].to_numpy(), settings.seed)
x = bc.condition_features(
    w.condition, vec["v"], vec["t_raw"], vec[f"t_aligned~{settings.heads_seed}"], null
)
policy, losses = bc.fit_bc(
    x[mask],
    frame["oracle_force"].to_numpy()[mask],
    hidden=hidden,
    layers=settings.layers,
    epochs=epochs,
    lr=settings.lr,
    weight_decay=settings.weight_decay,
    batch_size=settings.batch_size,
    seed=seed,
    device=torch_device(snakemake.params.device),
)
logger.info(
    "%s: %d demos, %d features, loss %.4f -> %.4f",
    w.condition,
    mask.sum(),
    x.shape[1],
    losses[0],
    losses[-1],
)
hashed.write_bytes(
    snakemake.output.weights,
    bc.save_bc(policy, hidden, settings.layers),
    rows=None,
    key=None,
    columns={},
    vectors={},
    producer=snakemake.rule,
    kind="weights",
)
curve = pd.DataFrame(
    {
        "row_id": [f"epoch-{i:04d}" for i in range(len(losses))],
        "epoch": range(len(losses)),
        "loss": losses,
    }
)
edges.write(snakemake.output.curve, curve, key="row_id", producer=snakemake.rule)
