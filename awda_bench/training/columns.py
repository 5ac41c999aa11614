"""Table S3's columns as training recipes: one ``(method, ablation)`` pair each.

====================  ==============  ================  =====  ====  =========================
column                ``--method``    ``--ablation``    ADM    TS    network
====================  ==============  ================  =====  ====  =========================
Full-1                awda            (none)            yes    yes   AwdaNet, 2 heads
single head           awda            single-head       yes    yes   AwdaNet, 1 head
no AD                 awda            no-ad             yes    no    AwdaNet, 1 head
no ADM                awda            no-adm            no     yes   AwdaNet, 2 heads
no waypoints          awda            no-waypoints      yes    yes   TosviNet (action head)
only waypoints        awda            only-waypoints    no     no    AwdaNet, 1 head
T-OSVI                tosvi           (none)            no     no    TosviNet
T-OSVI +depth         tosvi-depth     (none)            no     no    TosviNet + depth ResNet
====================  ==============  ================  =====  ====  =========================

Beside Table S3, the supplementary's §S3 analysis trains one more network (:data:`ANALYSIS_COLUMNS`):

=======================  ========  ================  =====  ====  ===========================
column                   method    ``--ablation``    ADM    TS    network
=======================  ========  ================  =====  ====  ===========================
T-OSVI, no frame-stack   tosvi     no-frame-stack    no     no    TosviNet, ``frame_stack = 1``
=======================  ========  ================  =====  ====  ===========================

With one frame there are no consecutive pairs, so this network has no inverse-model loss (the
supplementary does not say what its no-frame-stack model did with T-OSVI's inverse model; a stack of
one cannot feed it).

ADM = Asymmetric Demonstration Mixup; TS = trajectory-synthesis episodes in the training set
(AWDA: routed to head 1 when there are two heads; T-OSVI-style nets: plain extra samples).
Without TS data a second head would never receive a sample, so ``no-ad`` and ``only-waypoints``
build one head (the paper does not say; the evaluated head is the task head either way).
Shifts and colour jitter (the recipe's ``[augment]``) apply to every column: they are not an
ablation axis of Table S3. Full-2 (BC-Z data) and DAML have no counterpart here.
"""

from __future__ import annotations

from dataclasses import dataclass

from awda_bench.errors import UnknownChoiceError, UsageError

METHODS: tuple[str, ...] = ("awda", "tosvi", "tosvi-depth")
"""``--method`` values."""

ABLATIONS: tuple[str, ...] = (
    "single-head",
    "no-ad",
    "no-adm",
    "no-waypoints",
    "only-waypoints",
    "no-frame-stack",
)
"""``--ablation`` values (the first five ablate ``awda``; ``no-frame-stack`` ablates ``tosvi``)."""


@dataclass(frozen=True)
class Column:
    """What one Table S3 column trains."""

    name: str
    """Column label in Table S3."""
    method: str
    """``--method``."""
    ablation: str | None
    """``--ablation`` (``None``: the method itself)."""
    arch: str
    """Network architecture (snapshot ``arch``): ``awda``, ``tosvi`` or ``tosvi-depth``."""
    num_heads: int
    """AwdaNet waypoint heads (1 or 2; ignored for T-OSVI networks)."""
    adm: bool
    """Asymmetric Demonstration Mixup on training batches."""
    synthesized: bool
    """Trajectory-synthesis episodes are training samples."""
    frame_stack: int | None = None
    """T-OSVI-style nets: agent frames per sample, overriding the recipe's ``frame_stack``
    (``None``: the recipe's)."""

    @property
    def slug(self) -> str:
        """``awda``, ``awda+no-adm``, ``tosvi-depth``: the name a checkpoint directory records."""
        return self.method if self.ablation is None else f"{self.method}+{self.ablation}"


COLUMNS: tuple[Column, ...] = (
    Column("Full-1", "awda", None, "awda", 2, adm=True, synthesized=True),
    Column("single head", "awda", "single-head", "awda", 1, adm=True, synthesized=True),
    Column("no AD", "awda", "no-ad", "awda", 1, adm=True, synthesized=False),
    Column("no ADM", "awda", "no-adm", "awda", 2, adm=False, synthesized=True),
    Column("no waypoints", "awda", "no-waypoints", "tosvi", 1, adm=True, synthesized=True),
    Column("only waypoints", "awda", "only-waypoints", "awda", 1, adm=False, synthesized=False),
    Column("T-OSVI", "tosvi", None, "tosvi", 1, adm=False, synthesized=False),
    Column("T-OSVI +depth", "tosvi-depth", None, "tosvi-depth", 1, adm=False, synthesized=False),
)
"""Every trainable column of Table S3, in the table's order (module docstring)."""

ANALYSIS_COLUMNS: tuple[Column, ...] = (
    Column(
        "T-OSVI, no frame-stack", "tosvi", "no-frame-stack", "tosvi", 1,
        adm=False, synthesized=False, frame_stack=1,
    ),
)  # fmt: skip
"""Networks the supplementary's §S3 analysis trains beside Table S3 (module docstring)."""

TRAINABLE: tuple[Column, ...] = COLUMNS + ANALYSIS_COLUMNS
"""Every column ``train`` accepts."""


def column_for(method: str, ablation: str | None) -> Column:
    """The column ``(method, ablation)`` trains; unknown names and pairs are refused."""
    if method not in METHODS:
        raise UnknownChoiceError("method", method, METHODS)
    if ablation is not None and ablation not in ABLATIONS:
        raise UnknownChoiceError("ablation", ablation, ABLATIONS)
    for column in TRAINABLE:
        if column.method == method and column.ablation == ablation:
            return column
    owner = next(c.method for c in TRAINABLE if c.ablation == ablation)
    raise UsageError(
        f"--ablation {ablation} is an ablation of {owner}, not of {method}; "
        f"use --method {owner} --ablation {ablation}, or {method} without --ablation"
    )
