"""Layered window constructions get the U-factor and SHGC EnergyPlus rates them at.

The reference is EnergyPlus's Envelope Summary of the NREL 5-zone file itself (its own run,
the file's real box and windows), against the reader's rating run (a one-box model holding
one small window per construction).
"""

from __future__ import annotations

import json
import subprocess

import pytest
from zonecast.estimator.idf import (
    _glazing_table,
    _rate_layered_glazing,
    building_from_epjson,
    find_energyplus,
    load_epjson,
    read_building,
)

from tests.estimator.idf_text import BOX, HEADER

pytestmark = pytest.mark.energyplus


@pytest.fixture(scope="module")
def envelope_summary(five_zone_path, tmp_path_factory):
    """Glass U-factor and SHGC per window from EnergyPlus's run of the 5-zone file."""
    work = tmp_path_factory.mktemp("five_zone_envelope")
    data, _ = load_epjson(five_zone_path)
    data["Output:Table:SummaryReports"] = {"Output:Table:SummaryReports 1": {
        "reports": [{"report_name": "EnvelopeSummary"}]}}
    data["OutputControl:Table:Style"] = {"OutputControl:Table:Style 1": {
        "column_separator": "Comma"}}
    model = work / "in.epJSON"
    model.write_text(json.dumps(data))
    proc = subprocess.run([str(find_energyplus().binary), "-D", "-d", str(work), str(model)],
                          capture_output=True, text=True, timeout=900, check=False)
    table = work / "eplustbl.csv"
    assert table.is_file(), proc.stdout[-2000:]
    return _glazing_table(table.read_text())


def test_layered_windows_rated_as_energyplus_rates_them(five_zone, envelope_summary):
    assert envelope_summary  # the table was found and read
    for name, w in five_zone.windows.items():
        u, g = envelope_summary[name.upper()]
        assert (w.u_value, w.shgc) == pytest.approx((u, g), abs=0.0015), name
    cons = {w.construction: (w.u_value, w.shgc) for w in five_zone.windows.values()}
    # physics: a double clear pane loses half of a single one, gains less sun than clear
    assert 2.6 < cons["Dbl Clr 3mm/13mm Air"][0] < 2.9
    assert 5.8 < cons["Sgl Grey 3mm"][0] < 6.0
    assert not [u for u in five_zone.unsupported if u.reason.startswith("layered window")]
    assert any("rated by EnergyPlus" in n for n in five_zone.notes)


def test_without_energyplus_the_windows_stay_unrated(five_zone_path, tmp_path):
    data, notes = load_epjson(five_zone_path)
    building = building_from_epjson(data, notes)
    layered = sorted({w.construction for w in building.windows.values()})
    _rate_layered_glazing(building, data, layered, tmp_path)  # no EnergyPlus there
    assert all(w.u_value is None for w in building.windows.values())
    assert any("no EnergyPlus to rate" in n for n in building.notes)
    assert [u for u in building.unsupported if u.reason.startswith("layered window")]


OTHER_WINDOWS_IDF = HEADER + """
Building, W, 0, City, 0.04, 0.4, FullExterior, 25, 6;
GlobalGeometryRules, UpperLeftCorner, Counterclockwise, Relative;
WindowMaterial:Glazing:EquivalentLayer, Clear EQL, SpectralAverage, ,
    0.837, 0.837, 0.075, 0.075, 0.898, 0.898, 0.081, 0.081;
WindowMaterial:Gap:EquivalentLayer, Air EQL, Air, 0.0127, Sealed;
Construction:WindowEquivalentLayer, Double EQL, Clear EQL, Air EQL, Clear EQL;
Construction:WindowDataFile, From Window, Window5DataFile.dat;
""" + BOX + """
Window, Eql, Double EQL, S, , 1, 1, 1, 2, 1.5;
Window, Dat, From Window, N, , 1, 1, 1, 2, 1.5;
"""


def test_other_window_constructions_read_as_windows(tmp_path):
    """Equivalent-layer and data-file windows are windows (before, the reader failed on
    them): the equivalent-layer one with EnergyPlus's own rating, the data-file one unrated
    and reported."""
    idf = tmp_path / "in.idf"
    idf.write_text(OTHER_WINDOWS_IDF)
    b = read_building(idf)
    eql, dat = b.windows["Eql"], b.windows["Dat"]
    assert eql.area == dat.area == pytest.approx(3.0)
    assert 2.5 < eql.u_value < 3.0 and 0.6 < eql.shgc < 0.85  # double clear, 13 mm air
    assert dat.u_value is None and dat.shgc is None
    reported = {u.name for u in b.unsupported}
    assert "From Window" in reported and "Double EQL" not in reported
