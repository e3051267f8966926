"""Which recordings share a setup: the SESSION rule, used alike by the fit (its zero offsets) and the gap diagnosis
(its nuisances: force offset, contact shift, sensor lag). A session is one specimen mounted once; its nuisances
belong to it, not to a file, so a session split over several files (one per voltage, say) does not get a
per-file offset that could absorb a voltage-dependent effect.

The rule (docs/log-format.md, "Sessions"):
- a recording with a contact search (a native run): its own session, key `recording=<path>`;
- an imported recording (or specimen block) with a session label (CSV `session` column, or `import --session`):
  key `session=<label>|specimen=<specimen>` (a session is per specimen);
- an imported recording without one (the default): among the recordings given to one command, those with the
  same fixture, layer count (actuator) or design (leg) and specimen label ('' included) form one session: key
  `default|<fixture>|layers=<n>|design=<d>|specimen=<label>`.
"""

from __future__ import annotations

from typing import Any

RECORDING, EXPLICIT, DEFAULT = "recording", "explicit", "default"


def session_key(path: str, meta: Any, specimen: str, session: str, fixture: str,
                has_contact_search: bool) -> tuple[str, str]:
    """(key, rule) of one run (a recording, or one specimen block of an imported file). `meta`: its RunMetadata."""
    if has_contact_search or not meta.imported:
        return f"recording={path}", RECORDING
    if session:
        return f"session={session}|specimen={specimen}", EXPLICIT
    design = meta.design if fixture == "leg" else "-"
    return f"default|{fixture}|layers={meta.layers}|design={design}|specimen={specimen}", DEFAULT
