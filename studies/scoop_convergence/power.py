"""How many chains and paired seeds decide the paper's 0.6x: a power calculation from the committed summaries.

A chain is one draw of the training (demonstrations, spillage trials, policy, predictor); its
protocol runs pair every GRITS episode with DP's on the same seed. The measured inputs are read from
the committed `paired.csv` of each chain's summary (`CHAINS`), never typed:

- p_dp: DP's rate of spilling during the scoop, pooled over the chains;
- d: the share of paired episodes whose outcomes differ (discordance), pooled over the chains;
- tau: the between-chain spread of the log ratio log(GRITS/DP), estimated from the brim chains by
  the DerSimonian-Laird moment estimator (each chain's within variance from its paired counts,
  below); with two chains the estimate is poor, so the table is also given at the raw spread,
  tau = the standard deviation of the chains' log ratios (all of their difference taken as chain spread).

Model. K chains, N paired seeds each; GRITS's true rate is R p_dp. The pooled ratio is
sum(GRITS spills) / sum(DP spills) over all chains and seeds; with paired binary outcomes its log has
variance (b + c) / (G D) (b, c the discordant pairs, G, D the two methods' spills; the delta method on
the multinomial of the pairs), which at the expected counts is d / (K N R p_dp^2), plus tau^2 / K from
the chains. The study's interval is that log ratio +- 1.96 sd (a stratified bootstrap over chains and
seeds estimates the same spread). It *decides* when it excludes 0.6 or excludes 1:

    P(decided) = 1 - P(-z sd <= L <= log 0.6 + z sd),   L ~ Normal(log R, sd^2).

The table gives, per level, assumed truth R (the measured pooled ratio, and the paper's 0.6) and tau,
the fewest seeds per chain N at which P(decided) reaches 0.8 for K = 2, 3, 5, 10 chains ("never"
when tau alone keeps the interval wider than the gap at that K).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from grits_lab.errors import InputError
from grits_lab.intervals import Z_95

ROOT = Path(__file__).resolve().parents[2]
PAPER_RATIO = 0.6
TARGET_POWER = 0.8
CHAIN_COUNTS = (2, 3, 5, 10)
MAX_SEEDS = 1_000_000  # per chain: beyond this a design is reported as "never"


@dataclass(frozen=True)
class ChainRun:
    """One chain's paired GRITS-at-the-paper's-values against DP at one level: the summary and the method label in it."""

    level: str
    chain: str
    summary: str  # folder with paired.csv, relative to the repository root
    method: str  # the `method` column of GRITS at rho 2.5, s 30 in that file


# The two chains (the brim study's, and the one retrained from nothing on another CPU build), at brim and
# at the paper's levels (low and high): GRITS as the paper builds it, at the paper's values, against DP.
CHAINS = (
    ChainRun("brim", "first", "studies/brim_guidance/summaries/evaluate_cpu_brim_study", "grits[rho=2.5, s=30]"),
    ChainRun("brim", "retrained", "studies/brim_guidance/summaries/evaluate_cpu_brim_retrained", "grits"),
    ChainRun("paper levels", "first", "studies/protocol/summaries/evaluate_cpu_v12_rerun", "grits"),
    ChainRun("paper levels", "retrained", "studies/protocol/summaries/evaluate_cpu_study_retrained", "grits"),
)


def chain_counts(runs: tuple[ChainRun, ...] = CHAINS, root: Path = ROOT) -> pd.DataFrame:
    """One row per chain run: level, chain, paired, dp (DP spilled), grits, only_dp, only_grits."""
    rows = []
    for run in runs:
        path = root / run.summary / "paired.csv"
        if not path.is_file():
            raise InputError(f"{path}: missing (a committed summary the power calculation reads)")
        table = pd.read_csv(path)
        row = table[(table["reference"] == "dp") & (table["method"] == run.method)]
        if len(row) != 1:
            raise InputError(f"{path}: no single row of method {run.method!r} against dp")
        r = row.iloc[0]
        rows.append({"level": run.level, "chain": run.chain, "summary": run.summary, "paired": int(r["paired"]),
                     "dp": int(r["spillage_before"]), "grits": int(r["spillage_after"]),
                     "only_dp": int(r["spillage_only_before"]), "only_grits": int(r["spillage_only_after"])})
    return pd.DataFrame(rows)


def log_ratio_and_variance(grits: int, dp: int, only_dp: int, only_grits: int) -> tuple[float, float]:
    """log(grits / dp) and its paired delta-method variance (only_dp + only_grits) / (grits dp)."""
    if grits <= 0 or dp <= 0:
        raise InputError(f"a chain with {grits} GRITS and {dp} DP spills has no log ratio")
    return math.log(grits / dp), (only_dp + only_grits) / (grits * dp)


def between_chain_spread(rows: pd.DataFrame) -> tuple[float, float]:
    """(tau by DerSimonian-Laird, the raw standard deviation of the chains' log ratios) of `rows` (>= 2 chains)."""
    estimates = [log_ratio_and_variance(r.grits, r.dp, r.only_dp, r.only_grits) for r in rows.itertuples()]
    theta = [t for t, _ in estimates]
    weights = [1.0 / v for _, v in estimates]
    mean = sum(w * t for w, t in zip(weights, theta)) / sum(weights)
    q = sum(w * (t - mean) ** 2 for w, t in zip(weights, theta))
    scale = sum(weights) - sum(w * w for w in weights) / sum(weights)
    tau2 = max(0.0, (q - (len(theta) - 1)) / scale)
    raw = pd.Series(theta).std(ddof=1)
    return math.sqrt(tau2), float(raw)


def _normal_cdf(x: float) -> float:
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def decision_probability(ratio: float, p_dp: float, discordance: float, tau: float, chains: int, seeds: int) -> float:
    """P(the pooled ratio's 95 % interval excludes PAPER_RATIO or 1) for `chains` x `seeds` paired
    episodes, true ratio `ratio`, DP rate `p_dp`, discordance `discordance` and chain spread `tau`."""
    sd = math.sqrt(discordance / (chains * seeds * ratio * p_dp * p_dp) + tau * tau / chains)
    centre = math.log(ratio)
    upper = math.log(PAPER_RATIO) + Z_95 * sd  # L below it: the interval reaches 0.6
    lower = -Z_95 * sd  # L above it: the interval reaches 1
    undecided = max(0.0, _normal_cdf((upper - centre) / sd) - _normal_cdf((lower - centre) / sd))
    return 1.0 - undecided


def seeds_needed(ratio: float, p_dp: float, discordance: float, tau: float, chains: int) -> int | None:
    """The fewest seeds per chain at which `decision_probability` reaches TARGET_POWER; None when even
    MAX_SEEDS do not (the chain spread alone keeps it undecided)."""
    if decision_probability(ratio, p_dp, discordance, tau, chains, MAX_SEEDS) < TARGET_POWER:
        return None
    low, high = 1, MAX_SEEDS
    while low < high:  # P(decided) grows with the seeds
        mid = (low + high) // 2
        if decision_probability(ratio, p_dp, discordance, tau, chains, mid) >= TARGET_POWER:
            high = mid
        else:
            low = mid + 1
    return low


def power_table(counts: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(inputs per level, the design table) from `chain_counts`. Tau comes from the brim chains for every level."""
    tau_dl, tau_raw = between_chain_spread(counts[counts["level"] == "brim"])
    inputs, designs = [], []
    for level, rows in counts.groupby("level", sort=False):
        paired = int(rows["paired"].sum())
        p_dp = rows["dp"].sum() / paired
        discordance = (rows["only_dp"].sum() + rows["only_grits"].sum()) / paired
        measured = rows["grits"].sum() / rows["dp"].sum()
        _, within = log_ratio_and_variance(int(rows["grits"].sum()), int(rows["dp"].sum()), int(rows["only_dp"].sum()),
                                           int(rows["only_grits"].sum()))
        sd = math.sqrt(within + tau_raw * tau_raw / len(rows))  # the committed chains' own interval, at the raw spread
        inputs.append({"level": level, "chains": len(rows), "paired": paired, "dp": int(rows["dp"].sum()),
                       "grits": int(rows["grits"].sum()), "p_dp": p_dp, "discordance": discordance,
                       "measured_ratio": measured,
                       "ratio_low": measured * math.exp(-Z_95 * sd), "ratio_high": measured * math.exp(Z_95 * sd), "tau_dl": tau_dl, "tau_raw": tau_raw})
        for truth, ratio in (("measured", measured), ("paper", PAPER_RATIO)):
            if discordance < abs(ratio - 1.0) * p_dp:
                continue  # no paired distribution has this discordance at that ratio
            for tau_name, tau in (("dl", tau_dl), ("raw", tau_raw)):
                row = {"level": level, "truth": truth, "ratio": ratio, "tau_kind": tau_name, "tau": tau}
                for k in CHAIN_COUNTS:
                    row[f"seeds_k{k}"] = seeds_needed(ratio, p_dp, discordance, tau, k)
                designs.append(row)
    return pd.DataFrame(inputs), pd.DataFrame(designs)


def power_markdown(inputs: pd.DataFrame, designs: pd.DataFrame) -> str:
    from grits_lab.markdown import markdown_table

    lines = ["# How many chains and seeds decide the paper's 0.6x", "",
             "Generated by `python -m studies.scoop_convergence power` from the committed summaries below "
             "(studies/scoop_convergence/power.py states the model). Decided: the 95 % interval of the pooled "
             f"GRITS/DP spill ratio during the scoop excludes {PAPER_RATIO:g} or excludes 1, with probability "
             f"{TARGET_POWER:g}.", "", "## Measured inputs", ""]
    body = [[r.level, str(r.chains), str(r.paired), f"{r.grits} / {r.dp}",
             f"{r.measured_ratio:.3f} [{r.ratio_low:.3f}, {r.ratio_high:.3f}]", f"{r.p_dp:.3f}",
             f"{r.discordance:.3f}", f"{r.tau_dl:.3f}", f"{r.tau_raw:.3f}"] for r in inputs.itertuples()]
    lines += [markdown_table(["Level", "Chains", "Paired seeds", "GRITS / DP spills", "Pooled ratio [95 %, model]", "DP rate",
                              "Discordance", "tau (DL, brim)", "tau (raw, brim)"], body), ""]
    lines += ["The pooled ratio's interval is the model's (below) on the committed chains, at the raw chain spread.", ""]
    lines += ["Sources: " + ", ".join(f"`{run.summary}/paired.csv` ({run.level}, {run.chain} chain, `{run.method}`)"
                                       for run in CHAINS) + ".", "", "## Seeds per chain for P(decided) >= "
              f"{TARGET_POWER:g}", ""]
    body = [[r.level, f"{r.truth} ({r.ratio:.3f})", f"{r.tau_kind} ({r.tau:.3f})",
             *("never" if pd.isna(r[f"seeds_k{k}"]) else str(int(r[f"seeds_k{k}"])) for k in CHAIN_COUNTS)]
            for _, r in designs.iterrows()]
    lines += [markdown_table(["Level", "True ratio", "tau", *(f"K = {k}" for k in CHAIN_COUNTS)], body), ""]
    lines += ["## Reading", ""]
    for level, rows in designs.groupby("level", sort=False):
        raw = rows[rows["tau_kind"] == "raw"].set_index("truth")
        have = inputs[inputs["level"] == level].iloc[0]
        cells = [f"{_seeds(raw.loc[t, f'seeds_k{MIN_CHAINS}'])} seeds per chain if GRITS/DP truly is {raw.loc[t, 'ratio']:.3f} ({t})"
                 for t in raw.index]
        lines.append(f"- {level}: {MIN_CHAINS} chains (the fewest whose spread an interval can carry) need "
                     f"{' and '.join(cells)}, at the raw chain spread; the committed runs hold {have.chains} chains of "
                     f"{have.paired // have.chains} paired seeds.")
    lines += ["", "Limits: the interval is the normal approximation on the log ratio, rough below about 30 spills per "
              "method; tau is taken as known, estimated from two chains (with K chains a bootstrap over chains sees "
              "K - 1 degrees of freedom of it: two chains cannot carry it, hence at least three); DP's rate and the "
              "discordance are taken as the same in every chain.", ""]
    return "\n".join(lines)


MIN_CHAINS = 3  # the fewest chains whose spread a bootstrap over chains can estimate at all (issue: >= 3 chains)


def _seeds(value: float) -> str:
    return "never enough" if pd.isna(value) else str(int(value))


def power_report(summary_to: str | Path | None = None) -> str:
    """The power page (markdown); with `summary_to`, also written there with power.csv and inputs.csv."""
    inputs, designs = power_table(chain_counts())
    text = power_markdown(inputs, designs)
    if summary_to is not None:
        from grits_lab.io import ensure_writable_dir, write_text_atomic

        out = ensure_writable_dir(summary_to)
        write_text_atomic(out / "README.md", text + "\n")
        write_text_atomic(out / "inputs.csv", inputs.to_csv(index=False))
        write_text_atomic(out / "power.csv", designs.to_csv(index=False))
    return text
