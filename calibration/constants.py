"""Names and constants that a site file or a command line is checked against.

Apart from the modules that use them (:mod:`.solvers` imports every solver,
:mod:`.simulate` scipy), so that a program that only checks a name or a setting (the
daemon reading its site file before it puts the front-end in its safe state, a
command's ``--help``) does not import the engine.
"""

#: The solvers by name: ``reach-cal --method``, a site's and a schedule's ``solver``.
METHODS = ("radiometric", "thesis", "least-squares", "bayesian")
POLYNOMIAL_METHODS = ("radiometric", "thesis")
PER_CHANNEL_METHODS = ("least-squares", "bayesian")

#: iTPM channelisation: 400 MSPS sampled, 32768-point FFT.
ITPM_CHANNEL_WIDTH_HZ = 400e6 / 32768
