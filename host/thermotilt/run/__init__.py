"""The run folder every workflow shares: the twin, a campaign and ``log``
write it; fit, compare, validate, discover and hide-effect read it
(docs/run-log.md)."""

# Rows this soon after a run's start or a table move are left out of fits
# and comparisons: the firmware's Kalman filters, seeded at the first sample
# (lib/Kalman, ~10 s time constant), need ~90 s to forget a 45 deg step
# without RESEED (docs/run-log.md).
SETTLE_S = 120.0
