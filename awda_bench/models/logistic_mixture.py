r"""Discretized logistic mixture over bounded actions (PixelCNN++ style, as in T-OSVI).

Each action dimension in [low, high] is discretized into ``bins`` equally spaced values with half
bin width :math:`h = (high - low) / (2 (bins - 1))`. A mixture of M logistics with weights
:math:`\pi_m`, means :math:`\mu_m`, scales :math:`s_m` assigns value x the probability

.. math::

    P(x) = \sum_m \pi_m \left[\sigma\!\left(\tfrac{x + h - \mu_m}{s_m}\right)
                            - \sigma\!\left(\tfrac{x - h - \mu_m}{s_m}\right)\right],

with the lowest bin taking all mass below it and the highest all mass above. Log-probabilities are
computed in log space (``logsigmoid``/``softplus``), and where a bin's mass underflows the density
at the bin centre times the bin width stands in, so the NLL is finite for any parameters.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

MIN_LOG_SCALE = -7.0
"""Log-scales are clamped from below (scale >= e^-7) to keep the likelihood finite."""


class DiscretizedLogisticMixture:
    """Per-dimension mixture from raw parameters ``(..., D, 3 M)``: logits | means | log-scales."""

    def __init__(
        self, params: torch.Tensor, bins: int, low: float = -1.0, high: float = 1.0
    ) -> None:
        logits, means, log_scales = params.chunk(3, dim=-1)
        self.log_weights = torch.log_softmax(logits, dim=-1)  # (..., D, M)
        self.means = means
        self.log_scales = log_scales.clamp(min=MIN_LOG_SCALE)
        self.bins = bins
        self.low = low
        self.high = high
        self.half_bin = (high - low) / (2.0 * (bins - 1))

    def log_prob(self, x: torch.Tensor) -> torch.Tensor:
        """Log-probability ``(..., D)`` of actions ``x (..., D)`` (clipped to [low, high])."""
        x = x.clamp(self.low, self.high).unsqueeze(-1)  # (..., D, 1)
        centered = x - self.means
        inv_scale = torch.exp(-self.log_scales)
        plus_in = inv_scale * (centered + self.half_bin)
        minus_in = inv_scale * (centered - self.half_bin)
        log_cdf_plus = F.logsigmoid(plus_in)  # log P(X <= x + h): the lowest bin
        log_one_minus_cdf_minus = -F.softplus(minus_in)  # log P(X > x - h): the highest bin
        cdf_delta = torch.sigmoid(plus_in) - torch.sigmoid(minus_in)
        mid_in = inv_scale * centered
        log_pdf_mid = mid_in - self.log_scales - 2.0 * F.softplus(mid_in)
        log_bin_approx = log_pdf_mid + math.log(2.0 * self.half_bin)
        log_inner = torch.where(
            cdf_delta > 1e-5, torch.log(cdf_delta.clamp(min=1e-12)), log_bin_approx
        )
        edge = 1e-3 * (self.high - self.low)
        log_probs = torch.where(
            x < self.low + edge,
            log_cdf_plus,
            torch.where(x > self.high - edge, log_one_minus_cdf_minus, log_inner),
        )
        return torch.logsumexp(log_probs + self.log_weights, dim=-1)

    def mean(self) -> torch.Tensor:
        """Mixture mean ``(..., D)``, clipped to [low, high]."""
        return (self.log_weights.exp() * self.means).sum(-1).clamp(self.low, self.high)

    def mode(self) -> torch.Tensor:
        """Mean of the most probable component ``(..., D)`` (peak of a well-separated mixture)."""
        best = self.log_weights.argmax(dim=-1, keepdim=True)
        return self.means.gather(-1, best).squeeze(-1).clamp(self.low, self.high)

    def sample(self, generator: torch.Generator | None = None) -> torch.Tensor:
        """One sample per dimension ``(..., D)``, clipped to [low, high]."""
        weights = self.log_weights.exp()
        flat = weights.reshape(-1, weights.shape[-1])
        component = torch.multinomial(flat, 1, generator=generator).view(weights.shape[:-1] + (1,))
        mu = self.means.gather(-1, component).squeeze(-1)
        log_s = self.log_scales.gather(-1, component).squeeze(-1)
        u = torch.rand(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
        u = u.clamp(1e-5, 1.0 - 1e-5)
        return (mu + log_s.exp() * (torch.log(u) - torch.log1p(-u))).clamp(self.low, self.high)
