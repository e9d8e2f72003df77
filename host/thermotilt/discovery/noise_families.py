"""The noise a hidden-effect run can carry (``hide-effect --noise``), by
name; what each adds to the sensor is hide.py's. Named apart from it so the
command line offers them without importing numpy."""

NOISE_FAMILIES = {
    "model": "the model's own noise terms (white, flicker, drift slope per mounting)",
    "white": "white noise only",
    "flicker": "the model's with its flicker (1/f) floor 5x",
    "ar1-0.99": "white, plus a bias wander on each axis: AR(1), 0.99 per 10 Hz row (10 s)",
    "ar1-0.999": "white, plus a bias wander on each axis: AR(1), 0.999 per 10 Hz row (100 s)",
    "slope-0.5x": "the model's, its drift slope spread per mounting 0.5x what the model declares",
    "slope-2x": "the model's, its drift slope spread per mounting 2x what the model declares",
    "white-0.7x": "the model's, its white noise 0.7x what the model declares",
    "white-1.3x": "the model's, its white noise 1.3x what the model declares",
    "flicker-3x": "the model's, its flicker (1/f) floor 3x what the model declares",
    "cubic": "the model's, plus a drift term cubic in temperature as large as the paper's surfaces leave",
    "temperature-noise": "the model's, its temperature reading with 0.5 degC RMS of white noise per sample",
    "temperature-coarse": "the model's, its temperature reading in 1 degC steps, not 1/8",
}
