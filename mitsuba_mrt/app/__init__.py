"""The command line (:mod:`.cli`, parsing only), the ``render`` job that it
runs (:mod:`.job`) and image files (:mod:`.imageio`)."""
