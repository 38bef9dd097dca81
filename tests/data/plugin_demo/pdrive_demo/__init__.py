"""A demo drive family for pdrive: the Family row its entry point names (docs/plugins.md)."""

from profidrive_cli.drives.registry import Family


def family() -> Family:
    return Family(
        name="demo",
        codec="pdrive_demo.codec",
        drive_class="pdrive_demo.codec:DemoDrive",
        sim_model="pdrive_demo.sim:make_model",
        config="profidrive_cli.drives.profidrive.config:ProfidriveConfig.from_profile",
        profiles="pdrive_demo:profiles",
    )
