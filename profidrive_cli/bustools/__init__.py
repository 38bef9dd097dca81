"""Bus-level tools: what pdrive does with a PROFIBUS line without a drive session -- listening to it,
decoding what goes by, watching the live list, handing it to Wireshark. No module here opens a
DriveStation, starts a drive or writes a parameter; the passive ones never transmit.

Its place (tests/test_layering.py): beside session/. It may import link, fdl, dp, gsd, drives and the
top-level modules (profidrive_cli, datafile, outfile, data, config, plot) -- nothing of session, api,
checklist, cli or sim. The layers above session (api, checklist, cli) may import it. No click and
no rich: cli/sniff_cmd.py, sniff_view.py, scan_watch.py and wireshark_cmd.py render what it returns.

    listen.py        the passive reading loop of `sniff` and of the extcap capture (never transmits)
    passive.py       `sniff --station`: a watched station's captured Data_Exchange in the drive's words
                     (the families' offline decoders), sans-IO
    passive_live.py  `sniff --live`: DP state, ident, cycle time and counters per station from the
                     traffic alone, sans-IO
    triggers.py      the recorder's trigger language (lost(3), fault(7), cycle>20ms, ...): parsed with
                     the position in errors, evaluated on captured telegrams, sans-IO
    recorder.py      the black-box recorder (`sniff --ring`): the ring of telegrams, one capture per
                     event with the seconds before and after, bounded in seconds and telegrams, sans-IO
    dpv1view.py      sniff's DP-V1 acyclic telegrams in words (the PDU, the DS47 parameter request and
                     response, a call's request, SC, polls and answer tied together), sans-IO
    causes.py        likely causes from the live list's counters and timing, each with its evidence
    buswatch.py      `scan --watch` and the checklist step bus_health: the live list polled pass after
                     pass (Slave_Diag / FDL status through dp.poller.Master), state categories, counter
                     rates
    wireshark.py     `wireshark install`: the shipped dissector, the station table from the profiles,
                     the extcap launcher (written atomically)
    extcap.py        the extcap protocol answers and the live capture into Wireshark's fifo (until
                     SIGTERM, a closed fifo or Ctrl-C)

The package exports nothing of its own: import the module you need (profidrive_cli.bustools.passive).
"""
