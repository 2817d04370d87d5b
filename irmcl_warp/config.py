"""Typed config schemas (Hydra ConfigStore): a key that nothing reads is an error, not a silent no-op.

Units are in the key names. Paths of real data are relative to the data root (``IRMCL_DATA``, by
default ``../shared/data`` beside the repository).
"""

from __future__ import annotations

import builtins

from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING


@dataclass
class DataConfig:
    name: str = MISSING
    format: str = MISSING  # sim | carmen | bag
    path: Optional[str] = None  # scans + odometry
    laser_frame_path: Optional[str] = None  # a bag whose /tf_static gives base->laser (CARMEN logs carry none)
    ground_truth_path: Optional[str] = None  # matched CSV, TUM trajectory (.tum), or a GMapping-corrected CARMEN log
    ground_truth_time_offset_s: Optional[float] = None  # added to the ground truth's stamps to reach the log's clock
    ground_truth_max_gap_s: Optional[float] = None  # dense ground truth: SE(2)-interpolated at the scans between
    #                                                 poses at most this far apart; None: keyframes, matched by stamp
    ground_truth_tolerance_s: float = 1e-4  # keyframes: a pose stamped this close to a scan is that scan's
    ground_truth_fill: str = "none"  # keyframes: "odometry" poses the scans between them by the last keyframe plus
    #                                  the odometry since (how GMapping's own path between processed scans reads)
    relations_path: Optional[str] = None  # Kümmerle et al. 2009 relations
    relation_stamps_path: Optional[str] = None  # g2o file whose laser stamps stand in for synthetic log stamps
    splits_path: Optional[str] = None  # benchmark split ids (stamps)
    train_poses_path: Optional[str] = None  # poses the NOF trains on instead of the ground truth (the pipeline's SLAM)
    scan_topic: Optional[str] = None  # bags: auto when the bag has exactly one LaserScan topic
    odom_topic: Optional[str] = None
    base_frame: Optional[str] = None
    odom_frame: Optional[str] = None
    no_return_m: Optional[float] = None  # CARMEN: auto-detected as the most common maximum range
    fov_rad: Optional[float] = None  # FLASER carries no FOV; 180 deg unless set
    angle_min_rad: Optional[float] = None  # FLASER: angle of the first beam; -fov / 2 unless set
    laser_offset: Optional[List[float]] = None  # [x, y, yaw] of the laser on the base, in place of the one read
    beam_policy: str = "error"  # error | reject | resample scans whose beam count differs
    max_speed_mps: float = 3.0  # odometry faster than this between scans is reported as a jump
    max_step_m: float = 2.0
    repair_reversing: bool = False  # bags: drive backwards the odometry steps whose velocity is negative (fr079)
    scan_time_offset_s: float = 0.0  # bags: a scan's odometry is read at its stamp plus this (a scan stamped late: < 0)
    far_m: Optional[float] = (
        None  # the sensor's far bound for every stage (rendering, MCL, SLAM); None = floor(range_max)
    )
    split: str = "interleaved"  # interleaved (train/val/test) | block (train_block/val_block/test_block)


@dataclass
class SimConfig:
    seed: int = 0
    path_seed: Optional[int] = None  # another path (and noise) through the same world; None = seed
    width_m: float = 30.0
    height_m: float = 16.0
    corridor_width_m: float = 2.5
    room_min_width_m: float = 3.5
    room_max_width_m: float = 6.0
    door_width_m: float = 1.0
    furniture_per_room: int = 2
    repetitive: bool = False  # identical bays: perceptual aliasing
    visit_prob: float = 0.6
    speed_mps: float = 0.6
    turn_rate_rps: float = 0.8
    rate_hz: float = 5.0
    duration_s: Optional[float] = None
    num_beams: int = 360
    fov_rad: float = 4.71238898  # 270 deg
    range_max_m: float = 20.0  # the simulated lidar's largest reading (LaserScan.range_max)
    range_noise_std_m: float = 0.02
    dropout_prob: float = 0.01
    laser_x_m: float = 0.1
    odom_alphas: List[float] = field(default_factory=lambda: [0.05, 0.005, 0.05, 0.005])  # Thrun alpha1..4
    start_stamp_s: float = 1000.0


@dataclass
class MappingConfig:
    kernel: str = "logodds"
    resolution_m: float = 0.05
    l_occ: float = 0.85
    l_free: float = -0.4
    l_min: float = -4.0
    l_max: float = 4.0


@dataclass
class RaycastConfig:
    name: str = "dda"  # dda | distance_field
    occ_threshold: float = 0.5


@dataclass
class ModelConfig:
    """The NOF (IR-MCL Sec. III-A): 8 layers of 256, batch norm + ReLU, input again after layer 4, L = 10."""

    num_freqs: int = 10
    width: int = 256
    depth: int = 8
    skip_after: int = 4  # 0 = no skip connection


@dataclass
class RenderConfig:
    """Rendering ranges from the NOF (IR-MCL code: 256 samples, near 0.02 m, far = sensor range)."""

    name: str = "warp"  # warp | torch_ref
    num_samples: int = 256
    near_m: float = 0.02
    normalize: bool = True  # divide by the accumulated opacity, as the authors' code does
    t_min: float = 0.0  # early termination: skip samples with transmittance below this (0 = off)
    chunk_rays: int = 2048  # rays per forward pass when rendering without gradients


@dataclass
class TrainConfig:
    """The training recipe; presets in conf/train/ (paper = the authors' fr079 script)."""

    name: str = "paper"
    epochs: int = 32
    batch_rays: int = 1024
    num_samples: int = 256  # samples per beam while training (evaluation uses render.num_samples)
    perturb: bool = True
    lr: float = 1e-4
    lr_milestones: List[int] = field(default_factory=lambda: [4, 8])
    lr_gamma: float = 0.5
    lr_schedule: str = (
        "multistep"  # multistep (the authors': x lr_gamma after each milestone epoch) | cosine (per step, below)
    )
    warmup_steps: int = 0  # cosine: lr rises linearly from 0 over these steps ...
    lr_final: float = 0.01  # ... then falls along a cosine to lr * lr_final at the last step of the last epoch
    bn_recalibrate: int = (
        0  # before each validation, batch norm's running statistics recomputed over this many batches (0 = as trained)
    )
    ema_decay: Optional[float] = (
        None  # evaluate and keep an exponential moving average of the weights (e.g. 0.999); None = the weights themselves
    )
    weight_decay: float = 1e-3
    loss: str = "smooth_l1"  # smooth_l1 (authors' code) | l1 (paper)
    lambda_opacity: float = 1e-5  # weight of the occupancy regulariser (authors' code)
    amp: str = "off"  # off | bf16 (CUDA autocast for the MLP; rendering stays float32)
    tf32: bool = False
    max_time_s: Optional[float] = None  # stop training after this long (epochs still end cleanly)
    steps_per_epoch: Optional[int] = None  # None = one pass over the training rays
    val_scans: int = 100  # validation scans rendered after each epoch (evenly spread)
    compile: bool = (
        False  # torch.compile the network for the training pass (dynamic shapes; compiling counts as training time)
    )
    step_graph: bool = False  # CUDA: the whole step captured once as a CUDA graph and replayed (nof/step_graph.py)
    compile_mode: str = (
        "default"  # torch.compile's mode: default | reduce-overhead (CUDA graphs of the MLP's passes) | ...
    )
    fused_adam: bool = (
        False  # CUDA: Adam's update in one fused kernel (the same formula; ~1 ms less per step on an H100)
    )
    sampler: str = (
        "uniform"  # uniform (every sample through the MLP, the authors') | occupancy (irmcl_warp/nof/occupancy.py)
    )
    grid_resolution_m: float = 0.1  # occupancy sampler: cell size of the grid of the field's p_occ
    grid_threshold: float = 0.01  # a cell may be occupied above this p_occ
    grid_decay: float = 0.8  # value <- max(decay * value, p_occ at a random point of the cell)
    grid_every: int = 16  # steps between grid updates (the first at step 0)
    grid_dilate: int = 1  # cells added around every occupied one
    grid_end: str = (
        "field"  # where a beam's samples end: field (its transmittance, read without gradient) | grid | none
    )
    grid_t_min: float = 1e-4  # ... once that transmittance is below this
    fixed_samples: float = (
        0.0  # occupancy sampler: samples per beam through the MLP, fixed (0 = as many as the grid keeps)
    )
    fixed_samples_share: float = 0.0  # > 0: fixed_samples is this share of the samples per beam the starting grid keeps
    grid_masks_field: bool = False  # occupancy sampler: the field is read through the grid everywhere (validation, nof.pt, NOG): p = 0 in the cells it skips
    checkpoint_every_s: float = 120.0
    seed: int = 42


@dataclass
class MCLConfig:
    """Monte Carlo localization; IR-MCL's values (Kuang et al. 2023, Sec. IV and their configs) cited."""

    weighting: str = "nog_table"  # nog_table (IR-MCL's march read from a range table) | nog_raymarch (the march per particle and beam) | nof_direct | likelihood_field | beam_model
    num_particles: int = 100_000  # IR-MCL global localization
    num_beams: int = 32  # IR-MCL: 32 beams evenly spread over the scan
    beam_pick: str = "spread"  # spread (the paper: first to last beam) | stride (the authors' code: every (n // num_beams)-th from the first)
    num_samples: int = 256  # IR-MCL: samples per beam on the NOG
    near_m: float = 0.02
    t_min: float = 1e-3  # early termination once the transmittance is below (0 = the authors' formulation)
    empty_below: float = 0.0  # NOG nodes below this p_occ read as 0 and are jumped over (0 = authors')
    march_batch: int = 1  # NOG nodes loaded together per beam before compositing (1 = one at a time; same result)
    march_order: str = "beam"  # GPU threads by beam then particle (beam: 1.6x faster on an H100) | particle
    table_angles: int = 720  # nog_table: headings per NOG node in its range table (720: 0.5 deg apart)
    sigma_m: float = 0.5  # IR-MCL: likelihood exp(-0.5 D^2 / sigma^2), D the mean L1 beam error
    motion: str = (
        "odometry"  # odometry (Thrun / AMCL, noise mcl.alphas) | irmcl (IR-MCL's code, noise mcl.motion_noise)
    )
    alphas: List[float] = field(default_factory=lambda: [0.05, 0.005, 0.05, 0.005])  # Thrun a1..a4
    motion_noise: List[float] = field(
        default_factory=lambda: [0.01, 0.0005, 0.0002, 0.0005, 0.0001, 0.0001, 0.001, 0.00001, 0.05]
    )  # irmcl: C (variance = C |u|), the authors'
    estimate: str = "top_share"  # top_share (IR-MCL: weighted mean of the top 80 %) | best_cluster | mean
    estimate_share: float = 0.8
    cluster_cell_m: float = 0.5  # best_cluster: histogram cell (m) ...
    cluster_yaw_bins: int = 8  # ... and heading bins
    reduce_to: int = (
        5000  # IR-MCL: keep the 5k heaviest particles once converged (0 = never; when: localize.reduce_after_s)
    )
    update_min_trans_m: float = 0.0  # weigh and resample only after the odometry moved more than this ...
    update_min_rot_rad: float = 0.0  # ... or turned more than this (0/0: any motion, as IR-MCL's code)
    # (AMCL's update_min_d 0.2 m, update_min_a pi/6; ROS amcl wiki)
    first_update: str = "scan"  # scan: the first scan is weighed at once (IR-MCL's code) | motion: not before the
    # odometry passed the update_min_* gates (a robot standing still decides nothing from one view)
    temper: float = 1.0  # log w += temper * log p(z | x): 1 = the model's likelihood; below 1 tempered to fewer
    # independent beams (e.g. 4 / num_beams: beams 4 apart are about independent, AMCL's max_beams subsampling)
    # grid models' likelihood (AMCL's laser_* parameters, their ROS defaults; Thrun et al. Tables 6.1 and 6.3)
    z_hit: float = 0.95
    z_short: float = 0.1  # beam_model only
    z_max: float = 0.05  # beam_model only
    z_rand: float = 0.05
    sigma_hit_m: float = 0.2
    lambda_short: float = 0.1  # beam_model only
    field_max_dist_m: float = 2.0  # likelihood_field: end points farther from a wall count as this far (AMCL's
    # laser_likelihood_max_dist)
    field_occ_threshold: float = 0.65  # likelihood_field: cells at or above this p_occ are walls (map_server's
    # occupied_thresh)
    beam_occ_threshold: float = 0.5  # beam_model: rays stop in cells at or above this p_occ
    resample: str = "low_variance"  # low_variance | multinomial
    resample_threshold: float = 0.5  # resample when N_eff < threshold * N (1.0 = every step)
    map_resolution_m: float = 0.05  # NOG / grid resolution
    recovery_alpha_slow: float = 0.0  # AMCL's recovery (kidnapping): 0 = off; AMCL suggests 0.001
    recovery_alpha_fast: float = 0.0  # 0 = off; AMCL suggests 0.1
    step_graph: str = "auto"  # a step's launches replayed as one graph: auto (when capturable) | on | off
    # KLD-sampling (Fox 2003; AMCL's adaptive count): after each resampling the count becomes what keeps the
    # sample-based posterior's KL error below kld_err with quantile kld_z, for the bins the particles occupy,
    # between kld_min_particles and mcl.num_particles (kernels/kld.py)
    kld_sampling: bool = False
    kld_err: float = 0.01  # AMCL's kld_err (ROS amcl and nav2 default)
    kld_z: float = 0.99  # AMCL's kld_z: used as the normal quantile itself, as AMCL does (Fox's z_{1-delta})
    kld_min_particles: int = 500  # nav2 amcl's min_particles
    kld_cell_m: float = 0.5  # the histogram's cells: AMCL's kd-tree, 0.5 m x 0.5 m x 10 deg
    kld_cell_deg: float = 10.0
    # a global start's first update (after init_uniform: the start and every relocalization) weighs this many times
    # num_particles candidates spread uniformly, then keeps num_particles of them drawn by their tempered weights: one
    # update of a filter that many times larger (1 = off: the uniform set itself is weighed). Later updates run
    # with num_particles (ParticleFilter._first_from_candidates)
    global_candidates: int = 1
    cpu_threads: Optional[int] = None  # CPU only: motion and the grid models launched as a block of particles per core
    #   (None = the process's cores; 1 = one launch, which a CPU graph may capture); the same bits either way
    seed: int = 0


@dataclass
class SlamConfig:
    """GMapping (Grisetti et al. T-RO 2007); defaults = the released code / ROS wrapper's, named as there."""

    # (string fields say builtins.str: the odometry noise field below is named `str`, as in GMapping)
    num_particles: int = 30
    proposal: builtins.str = "paper"  # paper (Gaussian fitted around the match) | gmapping_code (the match) | odometry
    resample: builtins.str = "selective"  # selective (N_eff < threshold * N) | always
    resample_threshold: float = 0.5
    sigma: float = 0.05  # matcher score exp(-|mu|^2 / sigma)
    kernel_size: int = 1  # search window (2k + 1)^2 cells around each end point
    line: builtins.str = "bresenham"  # cells a beam clears: bresenham (the released code) | dda (every crossed cell)
    lstep: float = 0.05  # hill-climbing steps (m, rad), halved `iterations` times
    astep: float = 0.05
    iterations: int = 5
    lsigma: float = 0.075  # likelihood -|mu|^2 / lsigma
    ogain: float = 3.0  # weights smoothed as exp((l - max) / (ogain * N)) for N_eff and resampling
    lskip: int = 0  # use every (lskip + 1)-th beam in the likelihood
    null_likelihood: float = -0.5  # a beam without a match
    fullness: float = 0.1  # a cell is occupied above this hits / visits
    free_check: bool = False  # True: the matcher needs the cell before a hit free (False: the released code in effect)
    generate_map: bool = False  # True: particles' maps learn free space (False: end points only, the ROS wrapper's way)
    minimum_score: float = 0.0  # the match replaces the pose only above this score
    srr: float = 0.1  # odometry noise: translation from translation ...
    srt: float = 0.2  # ... rotation from translation
    str: float = 0.1  # translation from rotation
    stt: float = 0.2  # rotation from rotation
    linear_update: float = 1.0  # process a scan after this much travel (m) ...
    angular_update: float = 0.5  # ... or rotation (rad) ...
    temporal_update: float = -1.0  # ... or more than this many seconds after the last processed one; < 0: never
    # (the ROS wrapper's temporalUpdate; the released code's own default, which its gfs_nogui keeps, is 5 s)
    resolution_m: float = 0.05
    map_margin_m: float = 10.0  # the first map's half-size around the first pose, and the least slack the maps
    # get beyond a scan when they grow to hold it
    proposal_grid: int = 1  # paper proposal: (2g + 1)^3 poses around the match, spaced as below
    proposal_lstep: Optional[float] = None  # their spacing in x and y (m); None: lstep
    proposal_astep: Optional[float] = None  # and in theta (rad); None: astep
    frame: builtins.str = (
        "base"  # the poses the particles carry: base (the odometry's frame) | laser (the released code
    )
    # as its ROS wrapper feeds it: laser poses as odometry, so its motion noise, hill climbing and update distances
    # act on the laser; the same where the laser sits at the base)
    beam_angles: builtins.str = "log"  # log (the angles the log declares) | gfs (those the released code's own CARMEN
    # reader gives FLASER beams: irmcl_warp.io.carmen.gfs_flaser_angles; for a side-by-side run with its gfs_nogui)
    seed: int = 0


@dataclass
class GlobLocConfig:
    """Lidar + camera global localization (Gist retrieval, ORB + PnP, Scan2Map, relocalization trigger)."""

    scenario: str = "random_starts"  # the output folder's name: globloc-<scenario>
    methods: List[str] = field(default_factory=lambda: ["lidar_mcl", "camera_only", "paper", "mcl_seeded"])
    runs: int = 10
    run_s: float = 60.0
    kidnap_at_s: float = 0.0  # > 0: carry the robot to another start this far into each run
    lighting: float = 0.2  # relative exposure / tint change of the query sessions
    moved_furniture_m: float = 0.3  # furniture moved by up to this between mapping and query
    lookalike_share: float = 0.2  # posters that copy another one
    keyframe_every_m: float = 0.5
    keyframe_every_deg: float = 15.0
    gist_size: List[int] = field(default_factory=lambda: [120, 160])  # images resized to this (H, W) for the Gist
    gist_blocks: int = 4
    gist_orientations: List[int] = field(default_factory=lambda: [8, 8, 4])
    top_n: int = 20  # keyframes retrieved
    clusters: int = 3  # k-means of the candidates
    cluster_space: str = "pose"  # pose (x, y, heading) | index (the paper's: keyframe indices)
    pnp_per_cluster: int = 2  # keyframes of a cluster tried with ORB + PnP, best retrieved first
    orb_features: int = 1000
    ratio: float = 0.8  # Lowe's ratio test
    min_inliers: int = 12  # PnP accepted with more inliers than this
    scan2map: str = "paper"  # paper (sum of occupancy at the end points) | likelihood_field
    camera_every_s: float = 1.0
    max_speed_mps: float = 1.0  # the trigger: a winner farther than this speed allows since the last frame ...
    trigger_slack_m: float = 0.5
    trigger_margin: float = 0.2  # ... and a Scan2Map this much (relative) better than the tracked pose's
    trigger_search_m: float = 0.05  # the tracked pose's Scan2Map: the best within +-this (3 x 3 x 3 poses) ...
    trigger_search_rad: float = 0.02  # ... and +-this
    trigger_confirm_frames: int = 2  # ... confirmed by this many following frames' winners (1: the paper's)
    tracking_std: List[float] = field(default_factory=lambda: [0.3, 0.3, 0.1])
    seed_share: float = 0.1  # mcl_seeded: share of particles re-drawn around the camera's hypotheses
    num_particles: int = 20_000
    beams: int = 60
    recovery_alpha_slow: float = 0.01
    recovery_alpha_fast: float = 0.2
    map_resolution_m: float = 0.05
    success_trans_m: float = 0.5  # localized: within this and ...
    success_rot_deg: float = 15.0  # ... this of the truth, to the end of the run (or of the part before a kidnapping)
    seed: int = 0


@dataclass
class LocalizeConfig:
    """The localize stage: the benchmark protocol (IR-MCL Sec. IV: starts spread over a log with ground truth,
    scored), or with ``map_path`` a run of your own log in your own map (no ground truth needed)."""

    mode: str = "global"  # global (uniform over the free space) | tracking (from a noisy ground-truth pose)
    tracking_std: List[float] = field(default_factory=lambda: [0.5, 0.5, 0.3])  # tracking: initial spread (m, m, rad)
    num_starts: int = 10  # start times spread evenly over the sequence
    run_s: Optional[float] = 60.0  # how long each start is followed (map_path: None = to the end of the log)
    map_path: Optional[str] = None  # your map (ROS map_server YAML + PGM/PNG, or .npz): one run of data.* in it
    nof_path: Optional[str] = None  # map_path with mcl.weighting=nog_raymarch|nof_direct: your trained nof.pt
    initial_pose: Optional[List[float]] = None  # map_path: [x, y, yaw] in the map (RViz's "2D pose estimate"), spread
    #                                             tracking_std; None: global localization from a uniform start
    start_s: float = 0.0  # map_path: localize from this far into the log
    kidnap_at_s: float = 0.0  # > 0: teleport the robot this far into each run (to the next start's place)
    reduce_after_s: float = 20.0  # IR-MCL's code keeps the mcl.reduce_to heaviest particles 20 s into a global run
    relocalize: bool = False  # a run with a calibrated confidence (your map, mcl=amcl) runs the worlds stage's
    # lost-robot rule (mcl/worlds.LostRule, with the settings of conf/exp/worlds.yaml that the calibration and the rule
    # were chosen with) and says when it fires; true: it also starts again from a uniform spread then. Off by
    # default: on MIT Killian at 20k the rule fired while the estimate was right, at the same places of the log in
    # every seed, and each re-seed cost 10-40 s lost (0/4 by the protocol against 8/10; docs/benchmarks.md,
    # thirtieth session)
    report_pose: str = "mode"  # a run with a calibrated confidence (your map, mcl=amcl) reports at each update the
    # pose the confidence judged: the heaviest mode's (mode), as the worlds stage the calibration was fitted on does;
    # filter: the filter's estimate (mcl.estimate), a mean that lies between two clusters when the set holds two
    # (the own-map runs before the thirtieth session). Without a calibration the filter's estimate either way


@dataclass
class WorldsConfig:
    """Global localization on simulated floors nobody tuned on (issue 33; irmcl_warp/sim/floors.py): each world
    of the split mapped by a drive of its own, then ``runs`` other drives localized from their first scan."""

    split: str = "test"  # tuning | test (floors.SPLIT) | world names separated by "+" (office-7+loop-1003)
    runs: int = 10  # drives per world (path seeds 1..runs; the map's drive is seed 0)
    run_s: float = 60.0  # each drive localized for this long, from its first scan
    map_drive: str = "cover"  # the mapping drive: cover (every roadmap node: the map covers each room a drive can
    # enter) | random (a random drive map_drive_m long: the maps before the twenty-sixth session, which left rooms
    # unmapped that the test drives entered)
    map_drive_m: float = 400.0  # map_drive=random: its length (the map: log-odds of its scans at their true poses)
    map_logodds_limit: Optional[float] = None  # the map's log-odds bounded by +-this (None: unbounded: a static
    # floor's walls are not forgotten; 4.0: the maps before the twenty-seventh session, where the beams that graze a
    # wall on a long drive cleared it: mcl/worlds.py logodds_bounds)
    kidnap_at_s: float = 0.0  # > 0: that far into each run, the robot is carried to another drive's place
    unmapped_per_m: float = 0.0  # > 0: the drives see about this many objects per metre of drive that the map does
    # not hold (people, moved furniture: sim/floors.py with_unmapped), as real logs do; 0: only what was mapped
    calibration: Optional[str] = None  # the confidence's calibration (JSON of eval.confidence fit); None: the one
    # shipped for mcl.weighting (irmcl_warp/mcl/calibration/<weighting>.json), else features only; "off": features
    # only (the tuning runs a calibration of new features is fitted on)
    confident_above: float = 0.8  # a run ends "localized" only with its confidence at or above this
    lost_below: float = 0.2  # once localized, a confidence below this for lost_after_s ...
    lost_after_s: float = 1.0  # ... means lost: the filter starts again from a uniform spread and says so (1 s
    # against 2 s, chosen on kidnapped tuning runs by eval/gpu/worlds.sh's rule: results/worlds/lost_after_s.txt)
    lost_agreement_below: float = 0.0  # > 0: also lost when the scan's agreement with the map at the estimate ...
    lost_agreement_updates: int = 2  # ... stays below it for this many updates in a row (mcl/worlds.py LostRule;
    # off by default, as runs before it; +exp=worlds sets the pair chosen on tuning runs)
    lost_agreement_near_m: float = 0.0  # > 0: an update counts as low (lost_agreement_below) only where no pose
    lost_agreement_near_rad: float = 0.0  # within +-near_m and +-near_rad of the estimate agrees at or above it: an
    # estimate a fast turn left a few degrees behind its scan is not lost (0: the agreement at the estimate alone, as
    # runs before it; mcl/worlds.py LostRule.seen)
    lost_agreement_near_fit: float = 0.0  # ... and only where that best reaches this (0: lost_agreement_below)
    lost_timeout_agreement_below: Optional[float] = None  # the confidence's timeout (lost_below for lost_after_s)
    # counts only over updates whose scan agreement at the estimate (the feature agreement) is below this: an estimate
    # that explains the scans with another mode as likely is ambiguous, not lost, and a uniform re-seed would throw
    # its right mode away (None: every update counts, as in runs before it)
    mode_pose: str = "densest"  # a mode's pose: its densest cluster's (densest) | its 3 x 3 m block's weighted mean
    # (block: runs before the twenty-eighth session; mcl/confidence.py modes). The estimate is the heaviest mode's
    relocalize: bool = True  # False: only report when lost (side-by-side runs of the detector alone)
    relocalize_places: int = 0  # > 0: a relocalization's first update also weighs poses about this many places the
    # scan fits best over the whole map (ScanAgreement.search), beside the uniform candidates (mcl.global_candidates
    # > 1; 0: uniform only, as runs before it; mcl/worlds.py RelocalizePlaces)
    relocalize_keeps_particles: bool = False  # a relocalization's first update also weighs the particles the filter
    # had when declared lost, moved by the odometry since (False: as runs before it)
    refine_rivals: bool = False  # the confidence's rival places re-aligned with each scan (mcl/confidence.py,
    # FeatureTracker; False: moved by the odometry only)
    search_rivals_every: int = 0  # > 0: every this many updates, search the map's free space (0.5 m, 22.5 deg grid)
    # for places the scan fits as well as the estimate's, and keep them as rivals (0: rivals are former modes only)
    rival_seed_below: float = 0.0  # > 0: when a rival has explained the scans this much better than the estimate
    # (FeatureTracker's evidence, in scan shares summed over updates, <= -this), give rival_seed_share of the
    # particles its place and let the filter's weights judge (0: off, as runs before it; mcl/worlds.py)
    rival_seed_share: float = 0.5


@dataclass
class PipelineConfig:
    """The pipeline's second log, localized globally in the map and NOF made from the first (data.*)."""

    path: Optional[str] = None  # None: the simulator's second session (sim_path_seed below), or data.path again
    format: Optional[str] = None  # None = data.format
    ground_truth_path: Optional[str] = None  # poses to score against (same frame as data.ground_truth_path)
    sim_path_seed: int = 1  # data=sim: the second session drives this path through the same world
    train_every_scan: bool = True  # train the NOF on every scan (SLAM pose + odometry since), not only the processed
    start_s: float = 0.0  # localize from this far into the log ...
    run_s: Optional[float] = None  # ... for this long (None: to its end)


@dataclass
class Config:
    data: DataConfig = field(default_factory=DataConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    raycast: RaycastConfig = field(default_factory=RaycastConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    mcl: MCLConfig = field(default_factory=MCLConfig)
    slam: SlamConfig = field(default_factory=SlamConfig)
    globloc: GlobLocConfig = field(default_factory=GlobLocConfig)
    localize: LocalizeConfig = field(default_factory=LocalizeConfig)
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    worlds: WorldsConfig = field(default_factory=WorldsConfig)
    exp: str = "default"
    device: str = "auto"  # auto = cuda:0 when Warp sees a GPU, else cpu
    plugins: List[str] = field(default_factory=list)  # your own observation models / SLAM proposals: .py files or
    # modules imported before the settings are checked (irmcl_warp/extend.py)


def register() -> None:
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=Config)


CONF_DIR = (
    Path(__file__).resolve().parent / "conf"
)  # the experiment configs (pkg://irmcl_warp.conf: the top-level conf/)
CALIBRATION_DIR = Path(__file__).resolve().parent / "mcl" / "calibration"  # the localizers' confidence, one file
# per observation model (eval.confidence fit on the tuning worlds)


def shipped_calibration(weighting: str) -> Path | None:
    """The confidence calibration shipped for ``weighting``, or None."""
    path = CALIBRATION_DIR / f"{weighting}.json"
    return path if path.is_file() else None


def calibration_file(weighting: str, num_particles: int) -> Path:
    """Where the calibration fitted on the worlds stage's filter at this particle count lives (``<weighting>.json``
    for 20k, ``<weighting>-<n>k.json`` otherwise), whether or not one was fitted."""
    n = int(num_particles)
    return CALIBRATION_DIR / f"{weighting if n == 20000 else f'{weighting}-{n // 1000}k'}.json"


def own_map_calibration(weighting: str, num_particles: int) -> Path | None:
    """The calibration a run in your own map judges itself with: the one fitted at its particle count, or None."""
    path = calibration_file(weighting, num_particles)
    return path if path.is_file() else None


def worlds_calibration(weighting: str, num_particles: int) -> Path | None:
    """The calibration a worlds run that names none judges itself with: the one fitted at its particle count, else
    the weighting's 20k one (mcl/worlds.py calibration_of warns that it was fitted on another filter), else None."""
    return own_map_calibration(weighting, num_particles) or shipped_calibration(weighting)


def own_map_lost_rule_file() -> Path:
    """The settings a run in your own map declares its robot lost by: the worlds stage's (``+exp=worlds``), with which
    the calibration and the rule were chosen."""
    return CONF_DIR / "exp" / "worlds.yaml"


def own_map_lost_rule_settings():
    """``WorldsConfig`` with ``own_map_lost_rule_file()``'s worlds section over its defaults (what LostRule reads)."""
    from omegaconf import OmegaConf

    doc = OmegaConf.load(own_map_lost_rule_file())
    return OmegaConf.merge(OmegaConf.structured(WorldsConfig), doc.get("worlds", {}))


def compose_config(overrides=(), name: str = "config"):
    """``conf/<name>`` composed with Hydra ``overrides`` outside a Hydra app (benchmarks, reference checks)."""
    from hydra import compose, initialize_config_dir

    register()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(name, overrides=list(overrides))


class ConfigError(ValueError):
    """A setting outside what its key allows, or a key no schema declares."""


# choices of the string settings (a typo is an error, not a silent fallback); the registries and strategy tables
# that implement them sit above this module, so tests/test_config.py holds the two in agreement
CHOICES = {
    "data.format": ("sim", "carmen", "bag"),
    "data.ground_truth_fill": ("none", "odometry"),
    "data.beam_policy": ("error", "reject", "resample"),
    "data.split": ("interleaved", "block"),
    "raycast.name": ("dda", "distance_field"),
    "render.name": ("warp", "torch_ref"),
    "train.loss": ("smooth_l1", "l1"),
    "train.amp": ("off", "bf16"),
    "train.sampler": ("uniform", "occupancy"),
    "train.grid_end": ("field", "grid", "none"),
    "train.compile_mode": ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs"),
    "mapping.kernel": ("logodds",),
    "mcl.weighting": ("nog_raymarch", "nog_table", "nof_direct", "likelihood_field", "beam_model"),
    "mcl.estimate": ("top_share", "best_cluster", "mean"),
    "worlds.map_drive": ("cover", "random"),
    "worlds.mode_pose": ("densest", "block"),
    "mcl.beam_pick": ("spread", "stride"),
    "mcl.resample": ("low_variance", "multinomial"),
    "mcl.first_update": ("scan", "motion"),
    "localize.mode": ("global", "tracking"),
    "localize.report_pose": ("mode", "filter"),
    "slam.proposal": ("paper", "gmapping_code", "odometry"),
    "slam.resample": ("selective", "always"),
    "slam.line": ("bresenham", "dda"),
    "slam.frame": ("base", "laser"),
    "slam.beam_angles": ("log", "gfs"),
    "globloc.scan2map": ("paper", "likelihood_field"),
    "globloc.cluster_space": ("pose", "index"),
}
# numeric settings: (lowest, highest), None for no bound; a lowest written "> x" is exclusive
RANGES = {
    "data.far_m": ("> 0", None),
    "data.max_speed_mps": ("> 0", None),
    "data.max_step_m": ("> 0", None),
    "data.no_return_m": ("> 0", None),
    "data.fov_rad": ("> 0", 6.2832),
    "data.ground_truth_max_gap_s": ("> 0", None),
    "data.ground_truth_tolerance_s": (0, 1.0),
    "sim.rate_hz": ("> 0", None),
    "sim.num_beams": (1, None),
    "sim.range_max_m": ("> 0", None),
    "sim.speed_mps": ("> 0", None),
    "sim.width_m": ("> 0", None),
    "sim.height_m": ("> 0", None),
    "sim.dropout_prob": (0, 1),
    "sim.range_noise_std_m": (0, None),
    "mapping.resolution_m": ("> 0", None),
    "model.num_freqs": (1, None),
    "model.width": (1, None),
    "model.depth": (1, None),
    "model.skip_after": (0, None),
    "render.num_samples": (2, None),
    "render.near_m": (0, None),
    "render.t_min": (0, 1),
    "render.chunk_rays": (1, None),
    "train.epochs": (1, None),
    "train.batch_rays": (1, None),
    "train.num_samples": (2, None),
    "train.fixed_samples": (0, None),
    "train.fixed_samples_share": (0, None),
    "train.lr": ("> 0", None),
    "train.weight_decay": (0, None),
    "train.steps_per_epoch": (1, None),
    "train.val_scans": (1, None),
    "train.max_time_s": ("> 0", None),
    "train.checkpoint_every_s": ("> 0", None),
    "train.grid_resolution_m": ("> 0", None),
    "train.grid_threshold": (0, 1),
    "train.grid_decay": (0, 1),
    "train.grid_every": (1, None),
    "train.grid_dilate": (0, None),
    "train.grid_t_min": (0, 1),
    "mcl.num_particles": (1, None),
    "mcl.num_beams": (1, None),
    "mcl.num_samples": (2, None),
    "mcl.near_m": (0, None),
    "mcl.t_min": (0, 1),
    "mcl.empty_below": (0, 1),
    "mcl.table_angles": (4, None),
    "mcl.sigma_m": ("> 0", None),
    "mcl.estimate_share": ("> 0", 1),
    "mcl.cluster_cell_m": ("> 0", None),
    "mcl.cluster_yaw_bins": (1, None),
    "mcl.reduce_to": (0, None),
    "mcl.cpu_threads": (1, None),
    "mcl.update_min_trans_m": (0, None),
    "mcl.update_min_rot_rad": (0, None),
    "mcl.resample_threshold": (0, 1),
    "mcl.map_resolution_m": ("> 0", None),
    "mcl.recovery_alpha_slow": (0, 1),
    "mcl.recovery_alpha_fast": (0, 1),
    "mcl.temper": ("> 0", 1),
    "mcl.z_hit": (0, 1),
    "mcl.z_short": (0, 1),
    "mcl.z_max": (0, 1),
    "mcl.z_rand": (0, 1),
    "mcl.sigma_hit_m": ("> 0", None),
    "mcl.lambda_short": ("> 0", None),
    "mcl.field_max_dist_m": ("> 0", None),
    "mcl.field_occ_threshold": ("> 0", 1),
    "mcl.beam_occ_threshold": ("> 0", 1),
    "mcl.kld_err": ("> 0", None),
    "mcl.kld_z": (0, None),
    "mcl.kld_min_particles": (1, None),
    "mcl.kld_cell_m": ("> 0", None),
    "mcl.kld_cell_deg": ("> 0", 360),
    "mcl.global_candidates": (1, None),
    "worlds.runs": (1, None),
    "worlds.run_s": ("> 0", None),
    "worlds.map_drive_m": ("> 0", None),
    "worlds.kidnap_at_s": (0, None),
    "worlds.unmapped_per_m": (0, None),
    "worlds.confident_above": (0, 1),
    "worlds.lost_below": (0, 1),
    "worlds.lost_after_s": ("> 0", None),
    "worlds.lost_agreement_below": (0, 1),
    "worlds.lost_agreement_updates": (1, None),
    "worlds.lost_agreement_near_m": (0, 5),
    "worlds.lost_agreement_near_rad": (0, 1),
    "worlds.lost_agreement_near_fit": (0, 1),
    "worlds.lost_timeout_agreement_below": (0, None),
    "worlds.search_rivals_every": (0, None),
    "worlds.rival_seed_below": (0, None),
    "worlds.rival_seed_share": ("> 0", 1),
    "worlds.relocalize_places": (0, None),
    "localize.num_starts": (1, None),
    "localize.run_s": ("> 0", None),
    "localize.kidnap_at_s": (0, None),
    "localize.reduce_after_s": (0, None),
    "slam.num_particles": (1, None),
    "slam.resample_threshold": (0, 1),
    "slam.sigma": ("> 0", None),
    "slam.kernel_size": (0, None),
    "slam.lstep": ("> 0", None),
    "slam.astep": ("> 0", None),
    "slam.iterations": (0, None),
    "slam.lsigma": ("> 0", None),
    "slam.ogain": ("> 0", None),
    "slam.lskip": (0, None),
    "slam.fullness": (0, 1),
    "slam.srr": (0, None),
    "slam.srt": (0, None),
    "slam.str": (0, None),
    "slam.stt": (0, None),
    "slam.linear_update": (0, None),
    "slam.angular_update": (0, None),
    "slam.temporal_update": (None, None),
    "slam.resolution_m": ("> 0", None),
    "slam.map_margin_m": (0, None),
    "slam.proposal_grid": (0, None),
    "slam.proposal_lstep": ("> 0", None),
    "slam.proposal_astep": ("> 0", None),
    "globloc.num_particles": (1, None),
    "globloc.beams": (1, None),
    "globloc.runs": (1, None),
    "globloc.run_s": ("> 0", None),
    "globloc.kidnap_at_s": (0, None),
    "globloc.top_n": (1, None),
    "globloc.clusters": (1, None),
    "globloc.pnp_per_cluster": (1, None),
    "globloc.trigger_confirm_frames": (1, None),
    "globloc.map_resolution_m": ("> 0", None),
    "globloc.seed_share": (0, 1),
    "globloc.camera_every_s": ("> 0", None),
    "pipeline.start_s": (0, None),
    "pipeline.run_s": ("> 0", None),
}


def _in_range(v, lo, hi) -> bool:
    if isinstance(lo, builtins.str):
        ok = v > float(lo[2:])
    else:
        ok = lo is None or v >= lo
    return ok and (hi is None or v <= hi)


def validate(cfg, registered: dict | None = None) -> None:
    """Raise ConfigError naming the key and what it allows for a setting no schema declares (``+mcl.foo=1``),
    a choice that is not one of its choices, or a number outside its range. ``registered``: more choices per key,
    the names plugins registered (irmcl_warp/extend.py)."""
    import dataclasses

    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True)
    schema = {f.name: f for f in dataclasses.fields(Config)}
    for key, section in c.items():
        if key not in schema:
            raise ConfigError(f"{key}: no such setting (sections: {', '.join(sorted(schema))})")
        if isinstance(section, dict) and dataclasses.is_dataclass(
            schema[key].default_factory() if schema[key].default_factory is not dataclasses.MISSING else None
        ):
            declared = {f.name for f in dataclasses.fields(schema[key].default_factory())}
            extra = sorted(set(section) - declared)
            if extra:
                raise ConfigError(
                    f"{key}.{extra[0]}: no such setting in {key} (declared: {', '.join(sorted(declared))})"
                )
    for key, choices in CHOICES.items():
        choices = tuple(choices) + tuple(c for c in (registered or {}).get(key, ()) if c not in choices)
        sec, name = key.split(".")
        v = c.get(sec, {}).get(name)
        if v is not None and v not in choices:
            raise ConfigError(f"{key}={v!r}: expected one of {', '.join(choices)}")
    for key, (lo, hi) in RANGES.items():
        sec, name = key.split(".")
        v = c.get(sec, {}).get(name)
        if v is None or isinstance(v, bool):
            continue
        if not isinstance(v, (int, float)) or v != v or not _in_range(v, lo, hi):
            lo_text = lo if isinstance(lo, builtins.str) else (f">= {lo}" if lo is not None else "")
            bounds = " and ".join(b for b in (lo_text, f"<= {hi}" if hi is not None else "") if b)
            raise ConfigError(f"{key}={v!r}: expected a number {bounds}")


MIN_MEANINGFUL_PARTICLES = 50  # fewer particles cannot say how spread they are (a cloud of 2 reports 0.00 m)
MIN_MEANINGFUL_FAR_M = 1.0  # a far bound under this leaves almost every beam of a room unused


def settings_warnings(cfg) -> list[str]:
    """Settings that run but make the result meaningless, each said with the key and why."""
    out = []
    n = cfg.mcl.num_particles
    if n < MIN_MEANINGFUL_PARTICLES:
        out.append(
            f"mcl.num_particles={n}: a cloud this small cannot tell its own spread or find a global start "
            f"(below {MIN_MEANINGFUL_PARTICLES} its spread and convergence mean little)"
        )
    far_m = cfg.data.far_m
    if far_m is not None and far_m < MIN_MEANINGFUL_FAR_M:
        out.append(
            f"data.far_m={far_m}: every beam longer than {far_m} m is dropped, which in a building is nearly all"
        )
    return out
