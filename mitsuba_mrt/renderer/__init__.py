"""Everything that imports Mitsuba: variants, the trace, the plugins, the API.

Importing this subpackage imports Mitsuba; a variant must be active (see
:func:`mitsuba_mrt.activate`) before :mod:`.trace`, :mod:`.api` or
:mod:`.plugins` are used.
"""
