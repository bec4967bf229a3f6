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

#: The five noise-wave parameters, in the engine's order (thesis eq. 3.27): the
#: uncorrelated, cosine and sine noise waves, the noise source and the load.
PARAMETER_NAMES: tuple[str, ...] = ("unc", "cos", "sin", "NS", "L")

#: The most polynomial terms the order search gives one parameter
#: (:class:`calibration.choice.model_fit.OrderChoice`'s ``ceiling``; a test holds them equal).
ORDER_CEILING = 16

#: The twelve REACH calibrators (thesis table A.2), REACH names.
REACH_CALIBRATORS: tuple[str, ...] = (
    "cold", "hot", "r25", "r100", "c2r27", "c2r36", "c2r69", "c2r91",
    "c10open", "c10short", "c10r10", "c10r250",
)

#: Correlation length of the VNA's systematic error over frequency
#: (:mod:`calibration.checks.vna_systematics`).
DEFAULT_CORRELATION_HZ = 5e6

#: False-alarm rate of the calibrator consistency test (:mod:`calibration.checks.consistency`).
DEFAULT_ALPHA = 0.01

#: A calibrator below this (K) is taken for a Celsius slip unless declared cryogenic
#: (:mod:`calibration.checks.temperature_sanity`).
CELSIUS_SLIP_K = 150.0
