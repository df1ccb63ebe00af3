"""Root pytest hook: choose and activate a Mitsuba variant before collection.

Doctests of the Mitsuba-facing modules need a variant to import, so the
whole session runs on the variant that ``auto`` picks (LLVM if usable).
"""

import mitsuba_mrt

ACTIVE_VARIANT = mitsuba_mrt.activate("auto")
