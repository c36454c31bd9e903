"""Response and request bodies of the REST API (and of the MQTT state/forecast messages).

Every field states its unit; times are ISO-8601 with a UTC offset.
"""

from __future__ import annotations

from datetime import datetime

from pydantic import AwareDatetime, BaseModel, Field

__all__ = [
    "BuildingDetail", "BuildingSummary", "DiagnosisBody", "DiagnosisEffect", "ErrorBody",
    "ForecastBody", "GapItem", "GapPage", "GapSummary", "Health", "HistoryBody", "InternalGains",
    "ModelHealth", "OpenGap", "PointGaps",
    "Readiness", "StateBody", "TelemetryRefused", "TelemetryResult", "ZoneForecast", "ZoneGains",
    "ZoneHealth", "ZoneHistory", "ZoneState",
]


class ErrorBody(BaseModel):
    detail: str = Field(description="what is wrong and how to fix it")


class BuildingSummary(BaseModel):
    id: str = Field(description="building identifier (topic level and URL segment)")
    zones: list[str] = Field(description="model zones, in model order")
    model_version: str = Field(description="hash of the identified-model file")
    last_update: AwareDatetime | None = Field(
        description="time of the last processed step (UTC, ISO-8601); null before the first")


class BuildingDetail(BuildingSummary):
    timezone: str = Field(description="IANA time zone of the building (schedules, time of week)")
    latitude: float = Field(description="[deg north]")
    longitude: float = Field(description="[deg east]")
    step_s: float = Field(description="model step [s]")
    n_states: int = Field(description="number of model states [-]")
    boxes: list[str] = Field(description="VAV boxes (airflow inputs u), in model order")
    points: dict[str, str] = Field(description="telemetry point -> unit expected on the wire")
    parameters: dict[str, float] = Field(
        description="identified parameters (units in docs/model.md: W/m2K, -, W/m2)")
    notes: list[str] = Field(description="what the model file left at defaults")


class ZoneState(BaseModel):
    zone: str
    temperature: float = Field(description="filtered zone air temperature C x [degC]")
    std: float = Field(description="standard deviation of the estimate [K]")
    measured: float | None = Field(description="zone temperature measured at the last step "
                                               "[degC]; null if no sensor reported")


class OpenGap(BaseModel):
    point: str = Field(description="a point the site declares")
    since: AwareDatetime = Field(description="first 15-min step without a reading of it (UTC)")


class GapSummary(BaseModel):
    open: list[OpenGap] = Field(description="points without a reading since a step longer "
                                "ago than the tolerance, as of the last processed row")
    found: int = Field(description="gaps found since the runner started [-]")
    missing_steps: int = Field(description="point-steps without a reading since the runner "
                               "started, inside gaps or not [-]")
    tolerance_s: float = Field(description="runs of missing steps up to this long are not "
                               "gaps (runner.gap_tolerance) [s]")


class StateBody(BaseModel):
    building: str
    last_update: AwareDatetime | None = Field(
        description="time of the last processed step (start of its row, UTC)")
    data_freshness_s: float | None = Field(
        description="age of the newest stored reading relative to now [s]; null if none")
    update_age_s: float | None = Field(
        description="now minus last_update [s]; null before the first step")
    zones: list[ZoneState] = Field(description="per zone; empty before the first measurement")
    steps: int = Field(description="steps processed since the filter started [-]")
    nis_per_dof: float | None = Field(
        description="sum of normalised innovation squared / observed outputs since start [-]; "
                    "about 1 for a consistent filter")
    quality: list[str] = Field(
        description="flags: not_started, stale, missing_sensor:<zone>, held_input:<input>, "
                    "filter_restarted, never_received:<point> (no reading of the point in "
                    "any processed step), late_readings, gap:<point> (a gap of the point is open)")
    late_readings: int = Field(0, description="readings that arrived for steps already "
                               "processed since the runner started; stored, not used [-]")
    late_reading_times: list[AwareDatetime] | None = Field(
        None, description="earliest and latest time of the last late readings found (UTC)")
    gaps: GapSummary | None = Field(
        None, description="gaps in the telemetry the site declares (GET .../gaps lists them)")


class ZoneGains(BaseModel):
    zone: str
    online: float = Field(description="current online internal gains f_IG (paper "
                                      "eq:online_ig) [W/m2 of floor area]")
    last_estimate: float | None = Field(
        description="last per-step least-squares estimate f_IG(k-1) [W/m2]; null if the "
                    "step could not determine it")
    profile: list[float] = Field(
        description="fixed weekly profile, 672 bins of 15 min from Monday 00:00 local time "
                    "[W/m2]")


class InternalGains(BaseModel):
    building: str
    time: AwareDatetime | None = Field(description="last processed step (UTC)")
    profile_timezone: str = Field(description="IANA time zone of the profile's time axis")
    zones: list[ZoneGains]


class ZoneForecast(BaseModel):
    zone: str
    mean: list[float] = Field(description="forecast zone temperature per step [degC]")
    lower: list[float] = Field(description="lower end of the 90 % interval [degC]")
    upper: list[float] = Field(description="upper end of the 90 % interval [degC]")
    std: list[float] = Field(description="standard deviation of the forecast [K]")
    internal_gains: list[float] = Field(description="f_IG assumed per interval [W/m2]")


class ForecastBody(BaseModel):
    building: str
    issued: AwareDatetime = Field(description="issue time: the last measurement used (UTC)")
    model_version: str = Field(description="hash of the identified-model file")
    step_s: float = Field(description="spacing of the forecast times [s]")
    times: list[datetime] = Field(description="forecast times, issued + 15 min ... (UTC)")
    interval: float = Field(0.9, description="coverage of the interval [-]")
    zones: list[ZoneForecast]


class TelemetryRejection(BaseModel):
    point: str | None = Field(description="point of the rejected reading; null for the message")
    reason: str = Field(description="stable code, e.g. unknown_point")
    detail: str = Field(description="what was wrong")


class TelemetryResult(BaseModel):
    building: str
    accepted: int = Field(description="readings that passed validation [-]")
    stored: int = Field(description="readings newly stored [-]")
    duplicates: int = Field(description="readings already stored with the same key [-]")
    rejected: list[TelemetryRejection] = Field(description="readings rejected one by one")


class TelemetryRefused(BaseModel):
    detail: str = Field(description="why nothing was accepted: the message's reason, or the "
                                    "first readings' reasons")
    rejected: list[TelemetryRejection] = Field(
        description="the whole message (point null) or every reading, with reasons")


class Health(BaseModel):
    status: str = Field(description="'ok' while the process serves requests")


class Readiness(BaseModel):
    ready: bool = Field(description="storage answers, broker connected (if enabled), all "
                                    "models loaded")
    storage: bool
    broker: bool | None = Field(description="null when MQTT is disabled")
    models: dict[str, bool] = Field(description="building -> model loaded")
    errors: dict[str, str] = Field(description="component -> why it is not ready")


class ZoneHistory(BaseModel):
    zone: str
    measured: list[float | None] = Field(
        description="measured zone temperature per time (the model's y: the weighted mean of "
                    "the zone's sensors that reported) [degC]; null where none reported")


class HistoryBody(BaseModel):
    building: str
    step_s: float = Field(description="spacing of the times [s]")
    times: list[AwareDatetime] = Field(
        description="grid times of the window, ending at the last processed step (UTC); "
                    "empty before any reading")
    zones: list[ZoneHistory]


class ZoneHealth(BaseModel):
    zone: str
    innovation_rms: float | None = Field(
        description="RMS of the filter's innovations y - C x(t|t-1) over the steps of the "
                    "window processed since the service started [K]; null without any")
    innovation_steps: int = Field(description="innovations in that RMS [-]")
    missing_steps: int = Field(
        description="grid times of the window without a measurement of the zone [-]")
    last_measured: AwareDatetime | None = Field(
        description="latest time in the window with a measurement of the zone (UTC)")


class PointGaps(BaseModel):
    point: str
    missing: int = Field(description="grid times of the window without a reading [-]")


class ModelHealth(BaseModel):
    building: str
    window_start: AwareDatetime | None = Field(description="first grid time of the window (UTC)")
    window_end: AwareDatetime | None = Field(
        description="last grid time of the window: the last processed step (UTC)")
    window_steps: int = Field(description="grid times in the window [-]")
    last_update: AwareDatetime | None = Field(description="last processed step (UTC)")
    last_reading: AwareDatetime | None = Field(
        description="time of the newest stored reading (UTC); null if none")
    nis_per_dof: float | None = Field(
        description="normalised innovation squared per observed output since the filter "
                    "started [-]; about 1 for a consistent filter")
    zones: list[ZoneHealth]
    points_missing: list[PointGaps] = Field(
        description="points of the site with at least one grid time of the window without a "
                    "reading, most missing first")
    quality: list[str] = Field(description="the flags of /state")


class DiagnosisEffect(BaseModel):
    effect: str = Field(description="unmodelled effect (docs/diagnosis.md)")
    zones: list[str] = Field(description="zones with a fitted parameter")
    confident: bool = Field(description="confidence and score above the report's thresholds")
    score: float = Field(description="share of the training residual explained [-]")
    confidence: float = Field(description="1 - p of the per-day reductions [-]")
    heldout_rms_before: dict[str, float] = Field(
        description="zone (and 'mean') -> forecast RMS on held-out weeks without it [K]")
    heldout_rms_after: dict[str, float] = Field(
        description="zone (and 'mean') -> the same with the effect added [K]")


class DiagnosisBody(BaseModel):
    building: str
    available: bool = Field(description="a diagnosis report is configured and readable")
    file: str | None = Field(description="file name of the report (no folder)")
    modified: AwareDatetime | None = Field(description="when the report file was written (UTC)")
    detail: str | None = Field(description="why there is none, or null")
    effects: list[DiagnosisEffect] = Field(description="ranked effects, most likely first")


class GapItem(BaseModel):
    point: str = Field(description="a point the site declares")
    start: AwareDatetime = Field(description="first 15-min step without a reading (UTC)")
    end: AwareDatetime = Field(description="first step with a reading again (exclusive); for "
                               "an open gap the runner's next row (UTC)")
    steps: int = Field(description="steps without a reading, (end - start) / 15 min [-]")
    open: bool = Field(description="no reading of the point since start")


class GapPage(BaseModel):
    building: str
    total: int = Field(description="gaps matching the filters [-]")
    offset: int = Field(description="index of the first item in all matches [-]")
    next_offset: int | None = Field(description="offset of the next page; null on the last")
    tolerance_s: float = Field(description="runs of missing steps up to this long are not "
                               "gaps [s]")
    position: AwareDatetime | None = Field(
        description="the runner's next row: gaps are known up to here (UTC)")
    items: list[GapItem]
