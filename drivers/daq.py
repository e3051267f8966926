"""The DAQ backend surface the analog drivers need now lives in `hamr_bench.interfaces` (`DaqBackend`, `AiBlock`),
where the simulated DAQ can implement it without importing `drivers`; re-exported here for existing imports."""

from __future__ import annotations

from hamr_bench.interfaces import AiBlock, DaqBackend

__all__ = ["AiBlock", "DaqBackend"]
