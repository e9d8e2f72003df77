"""The noise a hidden-effect run can carry (``hide-effect --noise``), by
name; what each adds to the sensor is hide.py's. Named apart from it so the
command line offers them without importing numpy."""

NOISE_FAMILIES = {
    "model": "the model's own noise terms (white, flicker, drift slope per mounting)",
    "white": "white noise only",
    "flicker": "the model's with its flicker (1/f) floor 5x",
    "ar1-0.99": "white, plus a bias wander on each axis: AR(1), 0.99 per 10 Hz row (10 s)",
    "ar1-0.999": "white, plus a bias wander on each axis: AR(1), 0.999 per 10 Hz row (100 s)",
}
