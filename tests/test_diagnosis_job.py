"""`zonecast diagnose` (zonecast.jobs.diagnosis.run) hands the diagnosis a rebuilder of the
model with a zone's furniture scaled, built from the site's own EnergyPlus file."""

import numpy as np
import pytest


class _Stop(Exception):
    pass


def test_run_passes_a_furniture_rebuilder_of_the_sites_building(vb, tmp_path, monkeypatch):
    from zonecast.estimator.diagnose import _zone_states

    import zonecast.jobs.diagnosis as job

    seen = {}

    def fake(model, data, **kw):
        seen["model"], seen["kw"] = model, kw
        raise _Stop

    monkeypatch.setattr(job, "diagnose", fake)
    with pytest.raises(_Stop):
        job.run(vb / "model.json", vb, tmp_path / "diag")
    model, rebuild = seen["model"], seen["kw"]["mass_model"]
    assert callable(rebuild)
    states = _zone_states(model, ("internal_mass",))
    j = next(i for i, s in enumerate(states) if len(s))  # a furnished zone
    m2 = rebuild(j, 2.0)
    assert m2.n == model.n
    np.testing.assert_allclose(m2.structure.capacity[states[j]],
                               2 * model.structure.capacity[states[j]])
    others = np.setdiff1d(np.arange(model.n), states[j])
    np.testing.assert_allclose(m2.structure.capacity[others], model.structure.capacity[others])
    assert m2.params is model.params  # the identified parameters, not the start values
