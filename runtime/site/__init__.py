"""Site planning (``omnijax plan``): the rooms of a building, each optimised for several numbers of PTZs,
as tasks on Dask distributed; the site file, the room task and its check, and the cluster."""

from runtime.site.cluster import dask_client as dask_client, run_rooms as run_rooms
from runtime.site.rooms import choose as choose, containment_check as containment_check, plan_room as plan_room
from runtime.site.sitefile import RoomSpec as RoomSpec, SiteFile as SiteFile, load_site as load_site
