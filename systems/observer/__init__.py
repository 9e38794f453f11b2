"""Hawley, Rahem, Suleiman (2019): the two-stage Kalman force observer (eqs. 1-22), the
FSR/IMU measurement systems, compliant arms (eqs. 25-29), force-guided walking (Sec. 6.5)
and the authors' recorded Nao data."""
