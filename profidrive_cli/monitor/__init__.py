"""The line, monitored (`pdrive monitor`, issue 37): a listener left on a PROFIBUS line for weeks that
never transmits, and keeps what it hears -- the live list and per-station counters, the drives'
states and faults, the likely causes with their evidence, a capture around every event -- in a
history on disk, served as a web page, Prometheus metrics and MQTT alarms.

Its place (tests/test_layering.py): the `monitor` layer stands on bustools/ (and below it); cli/
stands on it. It never imports session, api, checklist, cli or sim: the virtual plant of
`--port 'sim://?timing=virtual&...'` is sim/virtual_line.py, handed in by the cli as a Link.

    model.py    the records every part shares: Sample, BusSample, StationInfo, MonEvent, StoreNote, the
                live view's shape (docs/monitor.md)
    engine.py   Monitor: sans-IO -- octets and their time in; events, captures, samples and the live
                view out (bustools' LiveList, TriggerSet, Recorder, causes and PassiveDecoder inside)
    store.py    History: the SQLite database and its captures directory, one disk bound over both
                (oldest first, counted), resumed after a restart, a full disk an event
    report.py   `pdrive monitor report`: what the history holds for a time window (and a station) as
                the JSON document, text and one HTML page
    web.py      the web page and its JSON, a WSGI application served by waitress (extra `monitor`),
                /metrics through metrics.py; loopback by default, a token on any other address
    metrics.py  the Prometheus text exposition of the live view (prometheus_client, extra `monitor`)
    mqtt.py     MQTT alarms on events (paho-mqtt, extra `mqtt`): a bounded queue, reconnects
    service.py  the loop: the port listened to (reopened after a loss), the engine fed, the history
                written, the live view handed to the page and the exporters, SIGTERM

No module imports an extra at load: web.py, metrics.py and mqtt.py import theirs inside the function
that needs it, so that `pdrive monitor` without `--web`/`--mqtt` runs on the default install.
"""
