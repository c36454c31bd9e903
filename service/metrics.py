"""Prometheus metrics of the service (``GET /metrics``), one registry per app.

Counters of the MQTT ingester and the REST ingest are read at scrape time; the step
latency is a histogram observed by the runners; innovation statistics and the age of
the last update are gauges computed at scrape time.
"""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from prometheus_client import CollectorRegistry, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric

if TYPE_CHECKING:  # the context creates the metrics (a cycle at run time)
    from zonecast.service.context import ServiceContext

__all__ = ["ServiceMetrics"]

_BUCKETS = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


class _Collector:
    def __init__(self, ctx: ServiceContext):
        self.ctx = ctx

    def collect(self) -> Iterator[Metric]:
        ctx = self.ctx
        mqtt = ctx.ingester.counters() if ctx.ingester is not None else {"rejected": {}}
        msgs = CounterMetricFamily("zonecast_messages", "telemetry messages received",
                                   labels=["transport"])
        msgs.add_metric(["mqtt"], mqtt.get("messages_in", 0))
        msgs.add_metric(["rest"], ctx.rest["messages_in"])
        yield msgs
        stored = CounterMetricFamily("zonecast_readings_stored", "readings newly stored",
                                     labels=["transport"])
        stored.add_metric(["mqtt"], mqtt.get("readings_stored", 0))
        stored.add_metric(["rest"], ctx.rest["readings_stored"])
        yield stored
        rej = CounterMetricFamily("zonecast_rejected", "messages or readings rejected, by "
                                  "reason code", labels=["transport", "reason"])
        for reason, n in sorted(mqtt.get("rejected", {}).items()):
            rej.add_metric(["mqtt", reason], n)
        for reason, n in sorted(ctx.rest_rejected.items()):
            rej.add_metric(["rest", reason], n)
        yield rej
        ingest = CounterMetricFamily("zonecast_ingest_errors", "MQTT ingest: failed storage "
                                     "writes (retried) and unexpected worker errors",
                                     labels=["kind"])
        ingest.add_metric(["storage"], mqtt.get("storage_errors", 0))
        ingest.add_metric(["worker"], mqtt.get("worker_errors", 0))
        yield ingest
        now = datetime.now(UTC)
        steps = CounterMetricFamily("zonecast_steps", "steps processed by the runner",
                                    labels=["building"])
        nis = GaugeMetricFamily("zonecast_nis_per_dof", "sum NIS / sum observed outputs since "
                                "the filter started (about 1 if consistent)", labels=["building"])
        last = GaugeMetricFamily("zonecast_nis_last", "NIS of the last update",
                                 labels=["building"])
        age = GaugeMetricFamily("zonecast_last_update_age_seconds", "now minus the time of the "
                                "last processed step [s]", labels=["building"])
        errors = CounterMetricFamily("zonecast_runner_errors", "failed runner polls",
                                     labels=["building"])
        late = CounterMetricFamily("zonecast_late_readings", "readings that arrived for steps "
                                   "already processed (stored, not used)", labels=["building"])
        gaps = CounterMetricFamily("zonecast_gaps", "gaps found in the telemetry the site "
                                   "declares (runs of missing steps beyond the tolerance)",
                                   labels=["building"])
        gap_steps = CounterMetricFamily("zonecast_gap_steps", "point-steps without a reading "
                                        "in rows the runner closed", labels=["building"])
        gaps_open = GaugeMetricFamily("zonecast_gaps_open", "points whose gap is still open",
                                      labels=["building"])
        for bid, r in sorted(ctx.runners.items()):
            gaps.add_metric([bid], r.gaps.gaps_found)
            gap_steps.add_metric([bid], r.gaps.missing_steps)
            gaps_open.add_metric([bid], len(r.gaps.open_gaps()))
        yield from (gaps, gap_steps, gaps_open)
        for bid, r in sorted(ctx.runners.items()):
            est = r.est
            steps.add_metric([bid], est.steps)
            errors.add_metric([bid], r.errors)
            late.add_metric([bid], r.late_readings)
            if est.dof_sum:
                nis.add_metric([bid], est.nis_sum / est.dof_sum)
            if r.last_report is not None and r.last_report.dof:
                last.add_metric([bid], r.last_report.nis)
            if est.time is not None:
                age.add_metric([bid], (now - est.time).total_seconds())
        yield from (steps, nis, last, age, errors, late)


class ServiceMetrics:
    """Registry and instruments of one app."""

    def __init__(self, ctx: ServiceContext):
        self.registry = CollectorRegistry()
        self.step_latency = Histogram("zonecast_step_latency_seconds",
                                      "wall time of one runner step (filter, f_IG, forecast, "
                                      "checkpoint) [s]", ["building"], buckets=_BUCKETS,
                                      registry=self.registry)
        self.registry.register(_Collector(ctx))

    def observe_step(self, building: str, seconds: float) -> None:
        self.step_latency.labels(building).observe(seconds)
