"""The demo family's simulated drive: pdrive's generic PROFIdrive model."""

from profidrive_cli.sim.profidrive_model import ProfidriveModel


def make_model(profile, **options):
    return ProfidriveModel(profile, **options)
