"""Every study (quick) writes its figure, curve and numbers."""

from vibinverse.studies import STUDIES

KEYS = {
    "fig2": {"max_displacement_m", "max_gradient"},
    "fig4": {"resonances_hz", "spectral_peaks_hz"},
    "fig6": {"wavelength_m", "continuity_error"},
    "fig8": {"view_offset_rad", "sensitivity"},
    "fig9": {"view_offset_rad", "sensitivity"},
    "fig10": {"amplitude_m", "sensitivity"},
    "fig11": {"incidence_rad", "sensitivity", "sensitivity_unpolarized"},
    "fig13": {"view_offset_rad", "sensitivity", "spectral_peaks_hz"},
    "fig14": {"sun_inclination_rad", "sensitivity"},
    "fig15": {"fov_width_m", "sensitivity"},
}


def test_every_study_writes_its_files_and_keys(results):
    out, lines, data = results
    for name in STUDIES:
        assert lines[name].startswith(f"{name}:") and "\n" not in lines[name]
        assert (out / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
        assert (out / f"{name}.csv").stat().st_size > 0
        assert KEYS[name] <= set(data[name])
