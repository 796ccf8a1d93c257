"""Paper Fig. 11 (quick): the p-polarized sensitivity peaks at Brewster's angle."""


def test_fig11_peaks_at_brewster(results):
    _, _, d = results
    f = d["fig11"]
    assert abs(f["peak_incidence_rad"] - f["brewster_rad"]) < 0.002
    assert f["peak_sensitivity"] > 0.5
    assert f["peak_sensitivity"] / f["sensitivity_unpolarized"] > 1000
