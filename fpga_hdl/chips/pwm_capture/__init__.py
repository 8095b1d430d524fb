"""Eight-channel PWM capture: pulse width, period and timeout per channel, RTL and TLM."""
