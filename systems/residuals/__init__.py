"""Flacco, Paolillo, Kheddar (2016): momentum residuals (eqs. 7, 11, 16), joint admittance
(eq. 14), contact force estimation, detection and localization (eqs. 15, 19, 20, 22), and
the residuals, detector and localizer replayed on a recorded log (``offline``: also the
detector's noise model from a calibration log)."""
