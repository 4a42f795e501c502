"""The model of a points campaign chosen by its held-out score: DH unless the encoder maps pay.

On SPATs the paper's proposed model (DH errors and an encoder map per axis) is the default: an
R-Test location's postures visit each map node many times. Absolute points of a robot are fewer and
spread over the whole joint space: 72 nodes per axis may outnumber what the points determine, and
the maps then fit the noise (a humanoid's 800 motion-capture points: 684 parameters, held-out
11.16 mm against 10.16 mm for DH). :func:`choose_model` fits both and keeps the proposed model
only where its held-out RMS (:class:`~aacmm_pin.analyses.linear_scorer.LinearScorer`: 5 folds of
whole poses, the arm's plausible sizes as priors, as ``discover`` scores) is below DH's;
:func:`heldout_check` is the same comparison for a model the user chose.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from aacmm_pin.data.campaign import Campaign
from aacmm_pin.fit.identification import identify
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.measurements import measurements
from aacmm_pin.model.arm import Arm
from aacmm_pin.progress import phase

# The held-out scorer (``linear_scorer``: the length bar's linearisation, validation, the
# discovery results) is imported where a comparison runs: an identify of SPATs needs none of it.

AUTO = "auto"
"""``identify --model auto``: the proposed model on SPATs; on points alone the one
:func:`choose_model` chooses."""


@dataclass(frozen=True)
class ModelChoice:
    """DH and proposed fitted to one campaign and compared on held-out poses."""

    calibration: Calibration
    """The fit of the model chosen (or given)."""
    heldout_rms: dict[str, float]
    """Model (``dh``, ``proposed``) -> held-out RMS per coordinate, m."""
    chosen: str
    """The model with the lower held-out RMS (DH on a tie): the better one on fresh poses."""

    @property
    def loses(self) -> bool:
        """Whether the calibration's model is not the one the held-out score chooses."""
        return self.calibration.model != self.chosen

    def text(self) -> str:
        """Return one line with both held-out RMS and the verdict (um)."""
        from aacmm_pin.analyses.linear_scorer import FOLDS

        cells = ", ".join(f"{m} {v * 1e6:.2f} um" for m, v in self.heldout_rms.items())
        return f"held-out RMS ({FOLDS} folds of poses): {cells}"

    def advice(self, auto: bool) -> str | None:
        """Return the line ``identify`` prints, or None where there is nothing to say.

        The choice made (``auto``), or a warning where the model given loses on held-out poses.
        """
        if auto:
            return (f"model {self.chosen} chosen: {self.text()} (--model auto: dh unless the "
                    "encoder maps predict left-out poses better)")
        if self.loses:
            return (f"WARNING: the {self.calibration.model} model loses on poses it was not "
                    f"fitted to: {self.text()}; its encoder maps fit the noise: use --model "
                    f"{self.chosen}")
        return None

    def to_dict(self) -> dict[str, Any]:
        """Return the ``report.json`` form (``model_choice``)."""
        from aacmm_pin.analyses.linear_scorer import FOLDS

        return {"heldout_rms_um": {m: v * 1e6 for m, v in self.heldout_rms.items()},
                "folds": FOLDS, "better": self.chosen}


def points_only(campaign: Campaign) -> bool:
    """Whether the campaign holds absolute points and no SPAT (the start model is then chosen)."""
    return campaign.points is not None and campaign.spat is None


def heldout_rms(cal: Calibration, campaign: Campaign, arm: Arm) -> float:
    """Return a calibration's held-out RMS per coordinate, m (``discover``'s start score)."""
    from aacmm_pin.analyses.linear_scorer import LinearScorer  # its imports: only when scored

    meas = measurements(campaign, arm, cal.use_rtest, "bar" in cal.inputs, cal.stated_noise)
    return LinearScorer(cal, meas.samples).heldout_rms


def _compare(fits: dict[str, Calibration], campaign: Campaign, arm: Arm
             ) -> tuple[dict[str, float], str]:
    """Return the held-out RMS of the fits that converged and the better model (DH on a tie)."""
    held = {m: heldout_rms(fits[m], campaign, arm) for m in ("dh", "proposed")
            if fits[m].success or fits[m].judged}
    inf = float("inf")
    return held, "proposed" if held.get("proposed", inf) < held.get("dh", inf) else "dh"


def heldout_check(cal: Calibration, campaign: Campaign, arm: Arm, **options: Any) -> ModelChoice:
    """Compare a fitted model with the other one (DH or proposed) on held-out poses.

    Args:
        cal: the fit of the model given (``dh`` or ``proposed``).
        campaign: its campaign.
        arm: its arm.
        options: the keywords ``cal`` was identified with (the other model is fitted with them).
    """
    other = "dh" if cal.model == "proposed" else "proposed"
    held, chosen = _compare({cal.model: cal, other: identify(campaign, arm,
                                                             **{**options, "model": other})},
                            campaign, arm)
    return ModelChoice(cal, held, chosen)


def choose_model(campaign: Campaign, arm: Arm, **options: Any) -> ModelChoice:
    """Fit DH and proposed to a points campaign; return the better on held-out poses.

    Args:
        campaign: a campaign of absolute points (:func:`points_only`).
        arm: the arm.
        options: keywords of :func:`~aacmm_pin.fit.identification.identify` but ``model``.
    """
    fits = {m: identify(campaign, arm, **{**options, "model": m}) for m in ("dh", "proposed")}
    held, chosen = _compare(fits, campaign, arm)
    return ModelChoice(fits[chosen], held, chosen)


def identify_model(campaign: Campaign, arm: Arm, model: str = AUTO, **options: Any
                   ) -> tuple[Calibration, ModelChoice | None]:
    """Identify as ``identify --model`` does; return the calibration and the comparison, if any.

    ``auto``: on points alone :func:`choose_model`, else the proposed model; ``proposed`` on
    points alone: compared with DH (:func:`heldout_check`); ``dh``: no comparison.

    Args:
        campaign: the campaign.
        arm: the arm.
        model: ``auto``, ``dh`` or ``proposed``.
        options: keywords of :func:`~aacmm_pin.fit.identification.identify` but ``model``.
    """
    if model == AUTO and points_only(campaign):  # points: DH unless the maps pay
        phase("identifying the dh and proposed models, compared on held-out poses")
        choice = choose_model(campaign, arm, **options)
        return choice.calibration, choice
    model = "proposed" if model == AUTO else model  # SPATs: the paper's model
    phase(f"identifying the {model} model")
    cal = identify(campaign, arm, model=model, **options)
    if model == "proposed" and points_only(campaign) and (cal.success or cal.judged):
        phase("checking the proposed model against dh on held-out poses")
        return cal, heldout_check(cal, campaign, arm, **options)
    return cal, None
