"""The command line (:mod:`.cli`, parsing only), the ``render`` job that it
runs (:mod:`.job`) and the ``batch`` command (:mod:`.batch`); image files are
:mod:`mitsuba_mrt.imageio`, shared with :mod:`mitsuba_mrt.bench`."""
