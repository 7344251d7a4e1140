"""The tuning constants of the interactive paths in one place: latency targets and delays,
sizes chosen for speed or memory, polling intervals and the adaptive models' weights (issue 47).

Code reads them as `TUNING.field` when it uses them, or when it builds the object that uses
them (a `DrawBudget`, a `HeapKeeper`, a queue's length, a session's latency target, the engine's
table cache), never copied into a module global, so that a test (or a bench) may set a field of
the one instance before the work or object it tunes: `monkeypatch.setattr(TUNING,
"refine_after_s", 0.0)`. Some tuning of other paths is still beside its code (the event
tracking's chunks and steps in flight, the widget's suspend delay, the OpenCL row blocks).

Each field has a comment saying what it tunes and how it was measured: the machine, the command
or case, the figure, and the commit that carries the measurement. "The 2-core machine" is the
project's development machine: 2 cores, PoCL for OpenCL and llvmpipe for GL. Where nothing was
measured, the comment says "not measured" and what the value was chosen as.

Constants that are not tuning have homes of their own: the limits the viewer's server enforces
in `chronocl.viewer.protocol.LIMITS`, the sizes of the annotations drawn on pictures in
`chronocl.render.layout.LAYOUT`; file formats, GL texture units and sizes baked into kernels
stay beside the code they size.
"""

from __future__ import annotations

from dataclasses import dataclass

MiB = 2**20


@dataclass
class Tuning:
    """The tuning constants, grouped by what they tune (one instance: `TUNING`)."""

    # --- The latency target ---

    # Milliseconds from input to its drawn frame that an interactive session aims at: a session
    # of level "auto" draws the finest level predicted within it (level 0 within
    # `sharp_overrun` of it), and the viewer draws a sharp frame whole where its draw fits it
    # (viewer/frames.py). Not measured: 150 ms reads as
    # immediate (docs/display.md; 5c608c6, 2026-11-23).
    target_ms: float = 150.0
    # Weight of the newest measurement in the adaptive models' running averages (`running`):
    # the measured rates of integrating, filling a sliding state, reading and displaying a
    # level and the cores a coarse frame keeps busy (`Costs`), and the draw budget's ms per
    # pixel (`DrawBudget`). Not measured: chosen as an even blend, so a slow frame moves the
    # choice back at once (5c608c6, e9a488f).
    smoothing: float = 0.5
    # A frame predicted within this many times the target is drawn sharp at once, not coarse
    # and refined after: drawn whole, not reduced and redrawn (viewer/frames.py), and at the
    # finest level, not a coarser one (`LatencyModel.pick`). Measured on the 2-core machine: a
    # sharp frame at 930x640 on llvmpipe draws in 130-170 ms, and one edit in two was drawn
    # twice, 150 ms more to the sharp frame (29ee9ea, 2026-11-28); a 256^3 slide in the notebook
    # widget, level 0 predicted at 160-250 ms, was drawn coarse, then integrated again at level
    # 0: sharp frame p50 294 ms against 174 ms drawn at level 0 at once (bench/
    # notebook_latency.py, 2026-12-01).
    sharp_overrun: float = 1.5

    # --- Delays of the viewer's frames ---

    # Seconds without input after a drag's coarse frame before it is refined to full resolution
    # (an edit's end refines at once). Not measured: chosen by hand as a short idle
    # (5c608c6, 2026-11-23).
    refine_after_s: float = 0.25
    # Seconds without input after a sharp frame of max, min, first_hit or change before the
    # winners are gathered, so that the first TF edit only recolours (new input gives the gather
    # up). Not measured: chosen by hand as a short idle (9ddf9eb, 2026-11-29).
    prepare_after_s: float = 0.3
    # Seconds a frame answering input works before it reports its progress (chronocl/viewer/
    # progress.py; the newest report held meanwhile is sent then). Not measured: chosen under
    # the page's 400 ms before its busy box shows (static/connection.js BUSY_AFTER_MS). What it
    # saves was measured on the 2-core machine, bench/notebook_latency.py at 256^3: a slide's
    # frames had sent about ten reports beside its two frames, 3 messages after (d536647,
    # 2026-12-01).
    frame_progress_after_s: float = 0.3
    # Seconds a frame waits, at most, for a client that left to let go of its frames. Measured
    # on the 2-core machine, bench/viewer_soak.py at 512^3: a reloaded page's first frame made
    # while the old socket's frames were held raised the peak by 1 GB; the bound itself is not
    # measured: chosen so that one busy client (a movie) stalls the others once (de9f115).
    left_wait_s: float = 30.0
    # Seconds a frame's send to a client may take before the client is taken for gone. Not
    # measured: chosen by hand, far above a frame's send (59cb087, 2026-11-22).
    send_timeout_s: float = 60.0

    # --- Draw size (viewer/frames.py's `DrawBudget`) ---

    # Milliseconds a frame answering input may spend drawing; the pixels drawn follow from the
    # measured ms per pixel. Measured on the 2-core machine: a 512^2 draw of 128^3 on llvmpipe
    # takes about 80 ms (80-140 ms, docs/display.md; 8d9063a, 2026-11-23).
    draw_target_ms: float = 80.0
    # Pixels of a sharp frame at most, over all its panels (the browser scales up beyond).
    # Measured in the browser tests: a 1400x900 page's single panel is 1024x733 and is drawn
    # whole (768^2 before drew it at 907x649; 2afd36b, 2026-11-23).
    pixel_budget: int = 1024 * 768
    # Pixels of a frame at least, however slow the draws: a floor on sharpness. Not measured:
    # chosen as 256^2 (8d9063a, 2026-11-23).
    min_pixels: int = 256 * 256
    # Scale of a preview frame's panels against the full frame. Not measured: chosen as half
    # the side, a quarter of the pixels (59cb087, 2026-11-22).
    preview_scale: float = 0.5

    # --- Work that may be given up (new input waits for one piece at most) ---

    # z-slabs of a texture write that may be given up (viewer/slots.py `upload`). Measured on
    # the 2-core machine, the users' case (bench/viewer_latency.py --users): the input wait
    # during a refine stays bounded; TF edit to sharp 1124 ms (8bceb38, 2026-11-27).
    upload_slabs: int = 8
    # Bands of rows of a draw that may be given up (render/raycaster.py `draw`). Measured on the
    # 2-core machine: a whole 930x640 draw of 512^3 takes 150-190 ms, so about 40 ms a band
    # (ab0a9f4, 2026-11-27).
    draw_bands: int = 4
    # Slabs of a winners' gather that may be given up (engine/gather.py). Measured on
    # the 2-core machine: at 512^3 and 10 steps the gather takes 1.2-1.4 s in all, so about
    # 0.2 s a slab (9ddf9eb, 1675ccd, 2026-11-29/30).
    gather_pieces: int = 8
    # z-slabs of a window integrated where it may be given up (a viewer's refine of a window
    # read in place or kept on the device; integration/interactive/level_session.py). Not
    # measured alone: chosen with the slab uploads that overlap them (5ee2bf9, 2026-11-26).
    refine_slabs: int = 8
    # A streamed window's slabs hold at least 1/stream_slabs of the volume. Measured on the
    # 2-core machine: with slabs of one row (a limit leaving no room) each chunk of the store
    # was decoded once a row, 96^3 x 8 steps streamed in 4.1 s, against 1.55 s in slabs of 6
    # rows and 1.0 s resident (e8b87a5, 2026-11-30).
    stream_slabs: int = 8

    # --- The viewer's memory ---

    # Bytes a full-resolution voxel of one view's frames holds beside the steps, counted against
    # --memory: the windows' steps stay resident only where they fit beside this for every view
    # (`ProcessLimit.window_room`; else they stream). Measured at 512^3 on the 2-core machine
    # (2026-11-30, bench/viewer_soak.py; 799aef2, docs/window.md): a max view held 17 bytes a
    # voxel steadily (its RGBA8 chronovolume and texture, t_index, u and step index) and 21 at
    # the peak of its switch, a second max view 17, an alpha view 8 steadily and 20 at the peak
    # of a TF edit. The steady 17 is counted: one view's transient at a time (up to 1.5 GB at
    # 512^3) lies within the 10% over the limit the soak's target allows.
    frame_voxel_bytes: int = 17
    # Textures of other shapes a panel keeps (viewer/slots.py `ViewSlot.texture`). Not
    # measured as a figure: two, so that coarse and full-resolution frames stop reallocating a
    # 512^3 texture each edit (dc27825, 2026-11-27).
    kept_textures: int = 2
    # Framebuffers of other sizes the raycaster keeps (render/raycaster.py `Raycaster._fbo`): a
    # page resized, or a frame drawn smaller while input comes (`DrawBudget`), asks for a new
    # size each time. Kept all, a minute of dragging held 74 of them, 160 MB (2026-12-01); four
    # cover a page's sharp and reduced frames with a second client's.
    kept_framebuffers: int = 4
    # Bytes the viewer's process may grow since its last clean-up before `HeapKeeper` collects
    # garbage and trims malloc. Measured with bench/viewer_soak.py (20 clients) on the 2-core
    # machine: without it the server grew ~100 MB/s without bound (86cb5ae, 2026-11-23).
    heap_allowance: int = 64 * MiB
    # Seconds between the viewer's heap checks. Not measured: chosen as once a second, cheap
    # beside the frames (86cb5ae, 2026-11-23).
    heap_check_s: float = 1.0

    # --- The TF editor's histogram (viewer/datasets.py) ---

    # Steps of the window sampled for the histogram, at most. Not measured: chosen so that a
    # window's histogram reads a handful of steps (3b4680f, 2026-11-23).
    hist_sample_steps: int = 8
    # Voxels of each sampled step, about (strided along every axis). Not measured: chosen as
    # 2^18, enough for a 128-bin histogram's shape (3b4680f, 2026-11-23).
    hist_sample_voxels: int = 2**18
    # The coarsest stored level with at least this many voxels is sampled. Measured on the
    # 2-core machine at 256^3 x 10: a cold window's histogram 423 -> 22 ms (32a8de9, 2026-11-27).
    hist_min_voxels: int = 2**15
    # Bytes decoded, at most, of a stored step without levels for its sample. Not measured:
    # chosen as 32 MiB, half a 256^3 float32 step (32a8de9, 2026-11-27).
    hist_read_bytes: int = 32 * MiB
    # Steps whose samples are kept (a window sliding by one reads one step). Not measured:
    # chosen above any window scrubbed (3b4680f, 2026-11-23).
    hist_cache_steps: int = 64
    # Per-(step, range) counts kept, a KiB each. Not measured: chosen as 4 MiB in all (32a8de9).
    hist_cache_counts: int = 4096
    # Bins of a histogram sent for the TF editor (the page draws as many as it gets). Not
    # measured: chosen as 128 (59cb087, 2026-11-22).
    hist_bins: int = 128

    # --- Host conversions and scans (render) ---

    # Floats per block of the texture conversion (render/upload.py): a block and its scratch
    # stay in L2 (256 KB). Not measured: chosen from the cache size (2fe5d52, 2026-11-23).
    upload_block_values: int = 2**16
    # Voxels below which the texture conversion runs as one task on the calling thread. Not
    # measured: chosen as 32^3 (2fe5d52, 2026-11-23).
    upload_serial_voxels: int = 2**15
    # Voxels below which the brick grid is built as one task on the calling thread
    # (render/brick_grid.py). Measured on the 2-core machine: 128^3 takes about a millisecond
    # that way (d51d892, 2026-11-27).
    brick_grid_serial_voxels: int = 2**21
    # Voxels read, at most, to frame the visible region (render/framing.py); larger volumes are
    # sampled with a stride. Not measured: chosen as 128^3 (16ccb5a, 2026-11-23).
    framing_sample_voxels: int = 2**21
    # Opacity above which a voxel counts as visible when framing the visible region
    # (render/framing.py; a tenth of the largest opacity where that is less). Not measured:
    # chosen as 2% (16ccb5a, 2026-11-23).
    visible_alpha: float = 0.02

    # --- Pictures' defaults (render/default_view.py, render/visible_steps.py, viewer) ---

    # Shifts of the window's centre of mass under this fraction of the box's half diagonal keep
    # the default view. Not measured: chosen by hand (f3de5ef, 2026-11-27).
    default_view_min_shift: float = 0.08
    # Cosine between the best side view and the shift under which the default view stays. Not
    # measured: chosen as 60 degrees (f3de5ef, 2026-11-27).
    default_view_min_align: float = 0.5
    # Pixels a selected step must change, at least (and 0.05% of the picture), when taken out,
    # to count as shown (`steps_shown`). Not measured: chosen by hand (f3de5ef, 2026-11-27).
    shown_step_pixels: int = 8
    # Change of a channel, in [0, 1], above which a pixel counts as changed by a step taken out.
    # Not measured: chosen as 3 of 255 levels, above rounding (f3de5ef, 2026-11-27).
    shown_step_level: float = 3 / 255
    # Fraction of a viewer panel's pixels visible below which the panel gets a note saying why
    # (viewer/frames.py). Not measured: chosen as 1% (2afd36b, 2026-11-23).
    empty_panel_fraction: float = 0.01

    # --- Slide or integrate (integration/interactive/costs.py) ---

    # Slides averaged for the steady slide's rate: longer than the splits' period (3/4 W
    # slides) at the widths scrubbed; tests/test_costs.py follows a machine getting slower.
    # Not measured as a time (e9a488f, 2026-11-30).
    slide_memory: int = 64
    # Guess, until measured, of a steady one-step slide, in voxel-steps of an integration from
    # resident steps. Measured on 2 PoCL cores with recycled partials (2026-11-30,
    # bench/slide_window.py and a forced `Session`, alpha and max): 12-33 at 128^3 W = 50,
    # 17-22 at 256^3 W = 50, 20 through the viewer (before partials were recycled, 30-70;
    # e9a488f).
    slide_steps: float = 20.0
    # Guess, until measured, of a sliding state's fill per window step, in voxel-steps. Measured
    # as slide_steps: 12 (128^3 alpha), 36 (128^3 max), 15-20 (256^3 alpha) per step (e9a488f);
    # 26-42 at 256^3 alpha through the viewer on 2026-12-01, slide_steps 21-26 (the fill's
    # partials are held at once, in fresh pages). Since then a state is filled once what the
    # window's integrated slides cost over slides reaches the fill (`costs.Move.rent`): a guess
    # too low fills a scrub's state too early, not one after every jump.
    fill_steps: float = 20.0
    # Idle cores a reader thread needs before full resolution is read ahead (a reader decodes
    # one step at a time). Not measured: one reader, one core (e9a488f, 2026-11-30).
    reader_cores: float = 1.0

    # --- Read-ahead while scrubbing (data/scrub_model.py) ---

    # Seconds after which a window request says nothing about the scrub now. Not measured:
    # chosen as a pause that ends a scrub (1b63474, 2026-11-27; bench/remote.py compares
    # time-aware, fixed and no prefetch).
    scrub_history_s: float = 1.5
    # Requests the scrub's speed is taken over (three intervals). Not measured (1b63474).
    scrub_history_n: int = 4
    # Steps under way beyond the bare speed x read time: reads queue behind each other. Not
    # measured: chosen as half again (1b63474, 2026-11-27).
    scrub_margin: float = 1.5
    # Weight of the newest step read in the running read time. Not measured (1b63474).
    scrub_read_weight: float = 0.3

    # --- Background work beside the frames (data/window.py, data/slots.py) ---

    # Seconds reads must have paused before free slots are warmed (faulted in). Measured on the
    # 2-core machine: an open faulted 8.4 GB in, 2 GB of it warming; 3.7-4.1 s to the sharp
    # frame with the pause against 4.6-12 s without (f53d46c, 2026-11-28).
    warm_after_s: float = 2.0
    # Nice value of the thread that warms slots: it takes idle cores only. Measured on the
    # 2-core machine: a write into a faulted-in 512 MB slot 0.07 s against 0.39 s fresh; the
    # value 10 itself not measured (88ff0a8, 2026-11-27).
    warm_nice: int = 10
    # Seconds between a waiting warm's looks at its caller's `ready`. Not measured (f53d46c).
    warm_poll_s: float = 0.2
    # Nice value of the window's reader threads, below the frames'. Measured on the 2-core
    # machine with the users' case (8bceb38, 2026-11-27: TF edit to sharp 1124 ms); the value
    # 10 itself not measured.
    reader_nice: int = 10
    # Seconds between a watched read's progress checkpoints (a refine's status line and its
    # chance to be given up). Not measured: chosen as 20 a second (5ee2bf9, 2026-11-27).
    watched_poll_s: float = 0.05
    # Seconds between garbage collections before a step slot of its own is allocated. Measured
    # in a viewer on the 2-core machine: a collection takes 30-130 ms (4df5470, 2026-11-27);
    # the interval itself not measured.
    collect_every_s: float = 5.0

    # --- Store reads ---

    # Steps read per zarr call by default, whose chunks zarr decodes concurrently (at most 10
    # at once, zarr's async.concurrency). Not measured as a figure: the plan tries 8, 4, 2, 1
    # and keeps the fastest that fits (090db62, 2026-11-22).
    steps_per_read: int = 8
    # Bytes of a chunk above which one landing in strided rows goes through zarr, not a scratch
    # buffer (each decode in flight holds a buffer of a chunk's size). Measured on the 2-core
    # machine: a 512^3 float32 step decoded on one thread directly 0.16-0.23 s against zarr's
    # 0.32 s (33bdb84, 2026-11-27); the bound itself not measured.
    scratch_bytes: int = 64 * MiB
    # Decode buffers kept between reads (their pages stay faulted in). Measured on the loaded
    # 2 cores: 10 x 256^3 float32 read into a brick 0.32-0.52 s against zarr's 0.47-0.61 s
    # (43f4b08, 2026-11-27); the count itself not measured.
    keep_buffers: int = 2
    # Bytes of the block a probe's run of steps holds at once, at most. Not measured (33ad41c).
    probe_read_bytes: int = 64 * MiB
    # Steps a probe reads at once, at most: zarr decodes the chunks of one read concurrently.
    # Not measured (33ad41c, 2026-11-23).
    probe_steps_per_read: int = 64
    # Seconds a probe runs before its progress bar appears. Not measured: chosen as 1 s
    # (33ad41c, 2026-11-23).
    probe_bar_after_s: float = 1.0
    # Voxel pairs compared per axis when judging a raw file's --dims order (`likelier_dims`).
    # Not measured: chosen as 2^20 (284d5cb, 2026-11-27).
    raw_dims_samples: int = 1 << 20
    # Voxels along an axis below which a raw file's --dims order is not judged (2D steps, a
    # few slices). Not measured: chosen as 4 once a 2D step always warned (d990dc8, 2026-11-27).
    raw_dims_min_side: int = 4

    # --- A raw file's misreadings (data/formats/raw_reading.py) ---

    # Float magnitude from which a reading is a misread, not data. Measured with the thresholds
    # below as one check (60e2e29, 2026-11-30): over vortex, plume, Gray-Scott and noise fields
    # written as float32, float64, uint16, int16 and uint8 in both byte orders at two sizes,
    # 0 false alarms on right readings, 0 wrong suggestions, 906 of 1134 misreads named.
    misread_beyond: float = 1e30
    # Roughness (of x neighbours, over the non-zero values) under which a reading is data.
    # Measured as misread_beyond (60e2e29).
    misread_smooth: float = 0.15
    # Times smoother than a rough given reading another must be to be named. Measured as
    # misread_beyond (60e2e29).
    misread_clearly: float = 1.5
    # Times smoother than a smooth given reading one of the same width must be to be named.
    # Measured as misread_beyond (60e2e29).
    misread_smoother: float = 3.0
    # Roughness under which a narrower type shows that a plausible wider reading is pairs of it.
    # Measured as misread_beyond (60e2e29).
    misread_narrower_smooth: float = 0.12
    # Neighbour pairs both non-zero below which a reading is not judged. Measured as
    # misread_beyond (60e2e29); a single-valued reading has no say since e485e74 (2026-11-30).
    misread_min_pairs: int = 64

    # --- Store writes ---

    # Bytes of a stored chunk, at most (data/writer.py: whole z planes). Not measured: chosen
    # as 16 MiB (63c131f, 2026-11-22).
    chunk_bytes: int = 16 * MiB
    # Level-0 bytes pooled at once, through every level, while in cache (data/pyramid.py). Not
    # measured: chosen as 2 MiB, to stay in cache (12e8eb9, 2026-11-23).
    pyramid_slab_bytes: int = 2 * MiB
    # Files uploaded at once to a remote store (data/remote_write.py). Not measured (30c3107).
    upload_concurrency: int = 16

    # --- Remote stores (data/remote_store.py) ---

    # Tries again of a failed remote read (CHRONOCL_REMOTE_RETRIES overrides). Not measured
    # (f8d0cac, 2026-11-27).
    remote_retries: int = 3
    # Seconds before the first try again, doubled each time (CHRONOCL_REMOTE_BACKOFF_S
    # overrides). Not measured (f8d0cac, 2026-11-27).
    remote_backoff_s: float = 0.2
    # Seconds, at most, for the remote reads given up to unwind (`settle`). Not measured:
    # chosen by hand (6a27545, 2026-11-30).
    remote_settle_s: float = 5.0

    # --- Host memory (core/memory.py) ---

    # Bytes from which an array gets an anonymous memory map of its own (`aligned_empty`).
    # Measured on the 2-core machine: with huge pages on a fragmented memory, 512 MB took
    # 1.6-10 s to fill where 4 KB pages take 0.4 s (33b54d6, 2026-11-27).
    mapped_bytes: int = 16 * MiB
    # Maps of dead outputs of one size kept for the next ones of that size: a viewer's frame in
    # max, min, first_hit or change holds three of 4 bytes a voxel (RGBA8, t_index, the winners'
    # u). Measured on the 2-core machine at 512^3: with two kept, the winners of the next
    # window's frame took fresh pages (the gather of the first edit after a mode switch 1.1 s,
    # 0.45 s on recycled memory with three; 050a132, 2026-11-27).
    spare_maps: int = 3
    # Sizes whose spare maps are kept (a chronovolume's rgba and t_index). Measured with
    # bench/integrate.py's race: with 2 maps in all, chronocl.integrate wrote on fresh pages,
    # 2x slower (be2ae09, 2026-11-28).
    spare_sizes: int = 2
    # Seconds spare maps are kept: memory nobody asks for again goes back. Measured at 10 x
    # 256^3 float32: recycled outputs 0.136 -> 0.054 s per call; the 30 s itself not measured
    # (050a132, 2026-11-27).
    spare_seconds: float = 30.0

    # --- Host threads and the process's memory (core) ---

    # Bytes below which a copy runs on the calling thread, not split over the host threads
    # (core/host_threads.py). Not measured: chosen as 4 MiB (5ee2bf9, 2026-11-27).
    parallel_min_bytes: int = 1 << 22
    # Seconds, at most, a piece of background work (a memory warm) waits for frames to pause:
    # frames made back to back (a view playing) must not hold it back for ever. Measured with
    # tests/test_foreground.py on the 2-core machine: an occupancy pass beside a 1 GB warm stays
    # within 3x its time alone (15x with the GIL-held warm); the 5 s itself not measured
    # (fe97f67, 2026-11-29).
    max_yield_s: float = 5.0
    # glibc's mmap threshold, fixed: every block of a MiB or more gets its own mapping, handed
    # back on free. Measured with tests/test_budget_threads.py: with glibc's sliding threshold
    # and 16 threads a 64 MB budget peaked at 1.25-1.4x (508962c, 2026-11-27).
    mmap_threshold: int = 1 << 20
    # glibc's trim threshold, set beside mmap_threshold: what an arena keeps free at its top.
    # Not measured: glibc's own default (508962c, 2026-11-27).
    trim_threshold: int = 128 << 10
    # Frames whose memory beside the steps a `ProcessLimit` keeps in mind (`need`). Not
    # measured: chosen as 8 (799aef2, 2026-11-29).
    recent_frames: int = 8
    # The viewer's own memory beside steps and frames (Python, the libraries, the OpenCL and GL
    # drivers). Measured at 512^3 on the 2-core PoCL/llvmpipe machine (2026-11-30): 383 MiB
    # fitted, the resident memory less the steps with one view and with two, the second view's
    # share taken off (9ecb08c).
    process_bytes: int = 400 * MiB

    # --- Notebook summaries' pictures (data/repr_html.py) ---

    # A summary picture's longest side, in voxels sampled (and pixels before scaling up).
    # Measured with the summaries as a whole on the 2-core machine: 6-190 ms at 256^3 (a coarse
    # level's or a strided projection, one slice of a store without levels); the size itself not
    # measured (0d3be74, 2026-11-30).
    repr_picture_voxels: int = 96
    # Coarse levels narrower than this are not pictured: a finer one is. Not measured (0d3be74).
    repr_min_side: int = 24
    # The picture's longest side on the page, CSS pixels. Not measured (0d3be74, 2026-11-30).
    repr_shown_px: int = 160

    # --- Engines ---

    # Integrations whose host and device tables an engine keeps (engine/tables.py
    # `TableCache`). Measured on the 2-core machine: kept tables took 0.65 -> 0.41 ms before
    # each enqueue of max on 30 x 128^3 (a 9 ms kernel); the count 16 not measured (970bbce).
    lut_cache: int = 16
    # Values from which a device-format conversion is split over the host threads
    # (engine/device_formats.py). Measured: float16 in numpy takes ~15 ns a value on one core
    # (bench/transfer.py, 71019dc, 2026-11-23); the threshold itself not measured.
    format_parallel_min: int = 1 << 18
    # Pieces of z rows per thread in the read roofline (engine/roofline.py), taken in turn by
    # whichever thread is free. Not measured: chosen as 8 (508962c, 2026-11-27).
    roofline_pieces_per_thread: int = 8

    # --- Value-range fitting (integration/fit_range.py) ---

    # Voxels sampled, at most, to fit a data TF's value range (4 MB of float32). Not measured:
    # chosen as 2^20 (f3de5ef, 2026-11-27).
    fit_sample_values: int = 1 << 20
    # Steps of the window sampled, at most, evenly spaced. Not measured (59cb087, 2026-11-22).
    fit_sample_steps: int = 16

    # --- Out-of-core and distributed runs (integration/runs) ---

    # Bytes of tables, small buffers and bookkeeping of one slab, in the plan's memory count.
    # Not measured: an allowance (a600fc0, 2026-11-22).
    run_base_bytes: int = 2 * MiB
    # Bytes each thread of a run holds besides the buffers counted: its stack pages, its malloc
    # arena's head and small blocks. Measured with tests/test_budget_threads.py: 16 forced
    # threads of each kind grew a run by 6-8 MB more than 2 did (508962c, 2026-11-27).
    run_thread_bytes: int = 256 * 2**10
    # Seconds before an unreachable dask scheduler is reported. Not measured (a600fc0).
    connect_timeout_s: float = 5.0
    # Slabs per worker thread of a distributed run: enough for every thread to take several
    # (load balance). Not measured (a600fc0, 2026-11-22).
    tasks_per_thread: int = 4


TUNING = Tuning()


def running(old: float | None, new: float, weight: float | None = None) -> float:
    """`new` taken into the running average `old` (None: `new` is the first measurement) with
    weight `weight` (None: `TUNING.smoothing`): the one average every adaptive model keeps."""
    w = TUNING.smoothing if weight is None else weight
    return new if old is None else (1 - w) * old + w * new
