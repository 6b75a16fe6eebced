"""The synthetic world (ground truth): scenes, people, lighting, sensor, omni and foveal rendering.

Nothing else in ``omnijax`` imports this package."""

from ._foveal import (
    HeadView as HeadView,
    PTZView as PTZView,
    foveal_head as foveal_head,
    head_in_view as head_in_view,
    ptz_view as ptz_view,
    render_foveal as render_foveal,
)
from ._image import (
    own_buffer as own_buffer,
    upsample as upsample,
)
from ._jpeg import (
    jpeg as jpeg,
)
from ._noise import (
    derive_key as derive_key,
    gaussian as gaussian,
    key_from_seed as key_from_seed,
    uniform as uniform,
    value_noise as value_noise,
)
from ._people import (
    Paths as Paths,
    People as People,
    body as body,
    body_distance as body_distance,
    draw_people as draw_people,
    walk as walk,
    walkable as walkable,
)
from ._render import (
    OmniBackground as OmniBackground,
    omni_rays as omni_rays,
)
from ._scenario import (
    Scenario as Scenario,
    parse_scenario as parse_scenario,
    read_scenario_header as read_scenario_header,
)
from ._scene import (
    xyz as xyz,
)
from ._sensor import (
    effective_sigma as effective_sigma,
    expose as expose,
    quantise as quantise,
)
from ._world import (
    FrameState as FrameState,
    RenderedFrame as RenderedFrame,
    Scene as Scene,
    Truth as Truth,
    World as World,
    build_world as build_world,
    draw_true_rig as draw_true_rig,
    render_frame as render_frame,
    render_frames as render_frames,
    render_state as render_state,
)
