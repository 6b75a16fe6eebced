"""The people detector: chromaticity, change measure, background and its life, polar indexing, the people
and their feet (eq 5-12)."""

from ._blobs import (
    People as People,
    a_person as a_person,
    find_people as find_people,
    merge_fragments as merge_fragments,
    own_feet as own_feet,
    own_lines as own_lines,
    parted as parted,
    window_count_prefix as window_count_prefix,
    window_sums as window_sums,
)
from ._change import (
    MEASURES as MEASURES,
    Background as Background,
    adapt_background as adapt_background,
    change_image as change_image,
    change_measure as change_measure,
    estimate_sensor_noise as estimate_sensor_noise,
    grey_change_measure as grey_change_measure,
    learn_background as learn_background,
    learned as learned,
)
from ._chroma import (
    chromaticity as chromaticity,
    chromaticity_covariance as chromaticity_covariance,
)
from ._detector import (
    Detections as Detections,
    DetectionTrace as DetectionTrace,
    Detector as Detector,
    LineBackground as LineBackground,
    build_detector as build_detector,
    detect as detect,
    find_sectors as find_sectors,
    life_candidates as life_candidates,
    line_background as line_background,
    line_change as line_change,
    lines_from as lines_from,
    locate_people as locate_people,
    polar_frame as polar_frame,
    with_zones as with_zones,
)
from ._foot import (
    FootSigmaTable as FootSigmaTable,
    foot_scores as foot_scores,
    foot_sigma_mc as foot_sigma_mc,
)
from ._indexing import (
    Sectors as Sectors,
    Thresholds as Thresholds,
    hysteresis_sectors as hysteresis_sectors,
)
from ._life import (
    CHANGED as CHANGED,
    Evidence as Evidence,
    Life as Life,
    LifeRates as LifeRates,
    floor_shows as floor_shows,
    ghost_evidence as ghost_evidence,
    learned_share as learned_share,
    live_step as live_step,
    regions as regions,
    set_aside_ghosts as set_aside_ghosts,
    settle_learning as settle_learning,
    start_life as start_life,
    verdicts as verdicts,
)
from ._polar import (
    PolarIndex as PolarIndex,
    build_polar_index as build_polar_index,
    polar_range as polar_range,
)
