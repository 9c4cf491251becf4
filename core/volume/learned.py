"""`attach_volume(body)` and `Volume`: the public VolumetricSMPL API attached to a body model.

    body = volsmpl.create_body()            # or smplx.create(...) SMPL / SMPL-H / SMPL-X
    volsmpl.attach_volume(body)
    out = body(betas=..., body_pose=..., global_orient=..., transl=...)
    sdf = body.volume.query(out, points)                    # (B, N), metres, negative inside
    part_sdf = body.volume.query_parts(out, points)         # (B, K, N)
    loss = body.volume.collision_loss(out, points)
    loss = body.volume.selfpen_loss(out)                    # (B,)
    mesh = body.volume.extract_mesh(out, resolution=128)

Data flow: body output -> partition (G_k, padded boxes, part surface samples) -> PointNet z_k ->
NBW decoder weights (only for the parts whose boxes hold query points; cached per body output and
grown by later queries; reused only while the output's values and the weights' values are the same,
checked by content fingerprints, volsmpl.volume.fingerprint) -> query: points to part frames, cull by boxes,
tiny decoders only on (point, part) pairs inside boxes (or densely, the reference path),
min over parts; points in no box get the analytic box SDF (paper eq. 4).
"""
from __future__ import annotations

import functools

import torch
from torch.profiler import record_function

from volsmpl.geometry.boxes import inside_boxes, near_boxes, part_normalization
from volsmpl.volume.code_refinement import refine_codes, refinement_points
from volsmpl.volume.refinement_setting import CodeRefinementSetting
from volsmpl.volume.warm_codes import WarmCodes
from volsmpl.volume.carried_passes import CarriedPasses
from volsmpl.volume.collision import reduce_penetration
from volsmpl.volume.engine.encode_graph import EncodeGraphs
from volsmpl.volume.encoding import Encoding, EncodingCache
from volsmpl.volume.engine.lean_query import DECODER_SCOPE, LeanQuery
from volsmpl.volume.models import kind_of_network, model_kind
from volsmpl.nn.analytic import box_sdf
from volsmpl.nn.pairs import group_counts
from volsmpl.nn.volsmpl_net import VolumetricSMPLNet
from volsmpl.body.partition import Partition
from volsmpl.volume.precision import check_precision, matmul_precision
from volsmpl.volume.engine.chunks import assemble_chunks, point_ranges
from volsmpl.volume.engine.query_graph import QueryGraphs
from volsmpl.volume.learned_selfpen import LearnedSelfPenetration
from volsmpl.volume.input_checks import check_points, nonfinite_points_error
from volsmpl.volume.api import BodyVolume, check_output


class Volume(EncodingCache, CodeRefinementSetting, LeanQuery, LearnedSelfPenetration, BodyVolume):
    """Volumetric extension of one body model (signed distance, or occupancy for COAP); see the module docstring.
    `attach_volume` builds it. Every switch below is also an attribute of the same name that may be changed on a
    built volume (precision through `set_precision`); `volsmpl bench` measures its variants by them
    (volsmpl.bench.variants).

    Args:
        net: the network: VolumetricSMPLNet (signed distance) or CoapNet (occupancy, the COAP baseline).
        partition: the body's parts (volsmpl.body.partition.Partition): part frames, padded part boxes and the
            surface samples the encoder reads.
        fingerprint: the fingerprint of the body model the volume belongs to (volsmpl.body.fingerprint).
        dense: False (default): part decoders only on the (point, part) pairs inside padded part boxes, the
            analytic box distance elsewhere. True: every part decoder on every point (the reference path; the
            same values and gradients).
        chunk_elems: memory budget of one query chunk in (body, part, point) entries, default 2^21: of the dense
            and 'chunked' paths, and of the lean path on the CPU, which also stops at `cpu_chunk_elems` (default
            CPU_CHUNK_ELEMS = 2^20); the lean path on other devices takes `gpu_chunk_elems` instead (default
            GPU_CHUNK_ELEMS = 2^24). Peak bytes per entry of one no-grad chunk at 60k points: on the CPU ~50 on
            'chunked', ~100 on 'lean' where most points are in no box (their box distances), less where most are
            in a box (commit 2674b94); on an H100 ~70 on 'lean' (538 MiB for the 7.7 M entries of B = 8 in one
            chunk, row 'volsmpl-onechunk' of `volsmpl bench --device cuda --batch 1 8 --points 60000`, commit
            508d1c0, docs/bench_cuda.md).
        engine: the sparse query path of SDF models, 'lean' (default) or 'chunked'; occupancy models (COAP) take
            the 'chunked' path either way. 'lean' (volsmpl.volume.engine.lean_query): one box test, the decoders
            on the pairs inside, their minimum by one scatter, box distances only for the points in no box, one
            host sync per chunk. 'chunked': every part's box distance at every point, then the minimum over a
            dense (B, K, N) array, in chunks of chunk_elems.
        pair_decoder: how the sparse path decodes its pairs, 'tiles' (default) or 'grouped'. 'tiles'
            (NBWDecoder.decode_pairs): without gradients on the CPU each (body, part) group's rows through its own
            weights, one addmm per layer and cache tile of 4,096 rows (volsmpl.nn.group_rows); otherwise the pairs
            cut into equal chunks of one group each, only each group's last chunk padded (~9 % of the rows on the
            benchmark's points), one batched matmul per layer. 'grouped' (volsmpl.nn.grouped): one grouped matmul
            per layer over all pairs, no padding, no tiles, so that the operator count depends neither on B nor
            on the pairs; it falls back to 'tiles' where the network or dtype has no grouped matmul (COAP,
            float64, float32 on CUDA). Against 'tiles' it was 1.3-2.5x slower on an AMD EPYC, as its activations
            leave the cache (commit 2a5c7fd); on an Intel Xeon at 60k points its query took 0.85x the time on one
            thread at B = 1, 1.25x on two, the same at B = 8 (bench variants 'volsmpl-grouped' and
            'volsmpl-tiles', commit 471cfd1).
        precision: the decoders' arithmetic on the sparse path (volsmpl.volume.precision, `set_precision`): 'full'
            (default: the volume's dtype), 'bf16' (the decoder layers in bfloat16 on the grouped engine, for
            networks that have one) or 'tf32' (float32 matmuls on TF32 tensor cores, CUDA only). The dense
            reference path always runs in full precision.
        cuda_graphs: True (default): the encode of a CUDA body output under torch.no_grad() replays a captured CUDA
            graph (volsmpl.volume.engine.encode_graph: one per batch shape, the eager encode's values bit for bit;
            all parts are encoded, also where a query needs only some). False: the encode runs op by op. No effect
            on a CPU, with autograd on (the apps' optimisation steps) or with code refinement. On an H200 at 60k
            points the replay took encode + query from 8.4 to 3.4 ms at B = 1 and from 9.5 to 6.4 ms at B = 8
            (`volsmpl bench --device cuda --models volsmpl,volsmpl-graphs --batch 1 8 --points 60000 --repeats
            10 --warmup 2 --budget 5 --quick --no-bodybody` at commit fcde88a, where 'volsmpl' encoded op by op
            and 'volsmpl-graphs' replayed; docs/bench_cuda.md).
        cuda_graph_queries: False (default): no-grad lean queries run eagerly. True: on CUDA they replay a captured
            static-shape query (volsmpl.volume.engine.query_graph: one per batch shape and pair capacity, the
            capacity learnt from the first, eager query of that shape; the eager query's values up to rounding;
            one host read, as the eager one), when the encoding holds all parts (`cuda_graphs` makes such
            encodings), the precision is 'full' or 'tf32' and the query is one lean chunk that needs the box
            distances (collision_loss's do not). Off by default as it has not been timed on a GPU (bench variant
            'volsmpl-qgraph' times it).
    """

    ENGINES = ("lean", "chunked")
    PAIR_DECODERS = ("tiles", "grouped")

    def __init__(self, net: VolumetricSMPLNet, partition: Partition, fingerprint: str,
                 dense: bool = False, chunk_elems: int = 1 << 21, engine: str = "lean", pair_decoder: str = "tiles",
                 precision: str = "full", cuda_graphs: bool = True, cuda_graph_queries: bool = False):
        super().__init__()
        self.net = net
        self.partition = partition
        self.fingerprint = fingerprint
        self.dense = dense
        self.chunk_elems = int(chunk_elems)
        self.cpu_chunk_elems = self.CPU_CHUNK_ELEMS
        self.gpu_chunk_elems = self.GPU_CHUNK_ELEMS
        if engine not in self.ENGINES:
            raise ValueError(f"engine must be one of {self.ENGINES}, got {engine!r}")
        if pair_decoder not in self.PAIR_DECODERS:
            raise ValueError(f"pair_decoder must be one of {self.PAIR_DECODERS}, got {pair_decoder!r}")
        self.engine = engine
        self.pair_decoder = pair_decoder
        self._last: Encoding | None = None
        self.decoder_evaluations = 0  # (point, part) decoder evaluations so far, for tests and benchmarks
        self.kind = kind_of_network(net)  # the registry's name of this model ('volsmpl', 'coap')
        self.set_precision(precision)
        self.refine_steps = 0   # set_code_refinement
        self.refine_warm = False
        self.warm: WarmCodes | None = None   # the open warm_start's state of warm code refinement
        self.passes = None      # set_passes (None: all the network's learned passes)
        self.pass_every = 1     # set_pass_interval
        self.carried: CarriedPasses | None = None   # the open warm_start's state of carried learned passes
        self.warm_serial = 0                 # warm_start scopes opened so far (part of the cache key)
        self.cuda_graphs = bool(cuda_graphs)
        self.encode_graphs = EncodeGraphs()  # the captured encodes (used when cuda_graphs is on)
        self.cuda_graph_queries = bool(cuda_graph_queries)
        self.query_graphs = QueryGraphs()    # the captured lean queries (used when cuda_graph_queries is on)

    def _frames(self, out):
        """Part transforms G (B, K, 4, 4) and padded part boxes (B, K, 3) x2 of a body output: no network."""
        p = self.partition
        G = p.part_transforms(out.full_pose, out.joints)
        return (G, *p.boxes(out.vertices, G))

    def _encode(self, out, generator, parts: torch.Tensor | None = None, frames=None, code_grad: bool = True) -> Encoding:
        """Encode all parts, or only `parts` ((K',) int64 ids, possibly empty; frames and boxes are kept
        for all K parts, the code is for `parts`, see Encoding). frames: (G, box_min, box_max) of `out`
        when already computed (see _frames). code_grad=False runs the encoder without autograd: the codes are
        constants and gradients reach the body only through the part frames and boxes (rigid part motion)."""
        v, dtype, where = out.vertices, out.vertices.dtype, self.partition.faces.device  # callers ran check_output
        if where != v.device or next(self.net.parameters()).dtype != dtype:
            raise ValueError(f"the body output is {dtype} on {v.device} but the volume is "
                             f"{next(self.net.parameters()).dtype} on {where}; move it with body.volume.to(device, dtype).")
        if generator is None and self._replays(out):
            enc = self.encode_graphs.run((self.net, self.partition), lambda o: self._encode_eager(o, None), out)
            if enc is not None:
                return enc
        return self._encode_eager(out, generator, parts, frames, code_grad)

    def _replays(self, out) -> bool:
        """Whether the encode of `out` (with the fixed surface samples) is a CUDA-graph replay: cuda_graphs on, a
        CUDA output, autograd off (EncodeGraphs.supports), no code refinement (fitted or learned); a key whose
        capture failed is then encoded eagerly."""
        return (self.cuda_graphs and not self.refine_steps and not self.active_passes
                and self.encode_graphs.supports(out))

    def _encode_eager(self, out, generator, parts: torch.Tensor | None = None, frames=None,
                      code_grad: bool = True) -> Encoding:
        """`_encode` without the CUDA-graph replay."""
        v = out.vertices
        p = self.partition
        G, box_min, box_max = self._frames(out) if frames is None else frames
        center = scale = None
        if getattr(self.net.config, "normalize_parts", False):
            center, scale = part_normalization(box_min, box_max)
        surface = p.surface_points(v, generator)  # (B, K, n, 3)
        Gs, cs, ss, slot = G, center, scale, None
        if parts is not None:
            surface, Gs = surface[:, parts], G[:, parts]
            if center is not None:
                cs, ss = center[:, parts], scale[:, parts]
            slot = torch.full((p.num_parts,), -1, dtype=torch.long, device=v.device)
            slot[parts] = torch.arange(len(parts), device=v.device)
        code = None
        if parts is None or len(parts):
            local = p.to_part_frames(surface, Gs)
            if center is not None:
                local = (local - cs[:, :, None]) / ss[:, :, None]
            with torch.set_grad_enabled(code_grad and torch.is_grad_enabled()):
                z = self.net.encode_z(local, parts, draws=p.draws)
                fit = bool(self.refine_steps) and generator is None and not self.training
                # the refinement points, made once and only where a pass or step needs them
                points = functools.cache(lambda: refinement_points(p, v, Gs, cs, ss, parts))
                passes = self.active_passes
                if passes:   # the learned passes, also in training
                    if self.carried is not None and generator is None and not self.training:
                        z = self.carried.apply(self.net, z, points, parts, passes)
                    else:
                        z = self.net.refiner(self.net, z, *points(), parts, passes=passes)
                if fit and self.warm is not None:
                    z = self.warm.refine(self.net, z, *points(), parts)
                elif fit:
                    z = refine_codes(self.net, z, *points(), parts, self.refine_steps)
                code = self.net.code_from_z(z, parts)
        return Encoding(G=G, box_min=box_min, box_max=box_max, code=code, center=center,
                        scale=scale, parts=parts, slot=slot)

    # ------------------------------------------------------------------ evaluation core
    @property
    def is_sdf(self) -> bool:
        """True for signed-distance models (VolumetricSMPL), False for occupancy models (COAP)."""
        return self.net.output == "sdf"

    @property
    def level(self) -> float:
        """The surface level: SDF 0, occupancy 0.5."""
        return 0.0 if self.is_sdf else float(self.net.config.level_set)

    def occupied(self, values: torch.Tensor) -> torch.Tensor:
        """Inside test of query/query_parts values: sdf < 0, or occupancy > level."""
        return values < 0 if self.is_sdf else values > self.level

    def to_signed(self, values: torch.Tensor) -> torch.Tensor:
        """query values -> the common sign convention, negative inside and positive outside: the signed distance
        itself (SDF models), level - occupancy for occupancy models (monotone, 0 on the surface, not metres)."""
        return values if self.is_sdf else self.level - values

    def _part_values(self, enc: Encoding, points: torch.Tensor, dense: bool):
        """points (B, N, 3) -> part (B, K, N), inside (B, K, N) bool (point in part k's padded box).

        SDF models: part k's decoder inside its box, the exact box SDF outside. Occupancy models:
        part k's occupancy inside its box, 0 outside (COAP's masking). A part without a code (subset
        encoding) is absent inside its box: +inf (SDF) / 0 (occupancy) there, and inside is False."""
        x_local = Partition.canonicalize(points, enc.G)
        inside = inside_boxes(x_local, enc.box_min, enc.box_max)
        if self.is_sdf:
            outside = box_sdf(x_local, enc.box_min[:, :, None], enc.box_max[:, :, None])
        else:
            outside = x_local.new_zeros(x_local.shape[:3])
        if enc.slot is not None:
            known = enc.encoded(self.num_parts)[None, :, None]
            outside = torch.where(inside & ~known, float("inf") if self.is_sdf else 0.0, outside)
            inside = inside & known
        norm = enc.scale is not None
        if dense:
            kk = slice(None) if enc.parts is None else enc.parts
            xs, ins = x_local[:, kk], inside[:, kk]
            if xs.shape[1] == 0:
                return outside, inside
            self.decoder_evaluations += xs.shape[0] * xs.shape[1] * xs.shape[2]
            extra = {} if self.is_sdf else {"inside": ins}
            with record_function(DECODER_SCOPE):
                if norm:
                    c, sc = enc.center[:, kk, None], enc.scale[:, kk, None]
                    vals = self.net.decode_dense((xs - c) / sc, enc.code, **extra) * sc[..., 0]
                else:
                    vals = self.net.decode_dense(xs, enc.code, **extra)
            vals = torch.where(ins, vals, outside[:, kk])
            return (vals if enc.parts is None else outside.index_copy(1, enc.parts, vals)), inside
        b, k, n = inside.nonzero(as_tuple=True)
        self.decoder_evaluations += b.numel()
        if b.numel() == 0:
            return outside, inside
        return outside.index_put((b, k, n), self._decode(enc, x_local, b, k, n)), inside

    def _grouped_ok(self, x: torch.Tensor) -> bool:
        """Whether the pairs x (M, 3) are decoded by grouped matmuls (pair_decoder, network, dtype and device)."""
        return (self.pair_decoder == "grouped" and model_kind(self.kind).grouped
                and self.net.grouped_supported(x.dtype, x.device))

    def _decode(self, enc: Encoding, x_local: torch.Tensor, b, k, n) -> torch.Tensor:
        """Decoder values of the pairs (b, k, n) (each (M,) int64) of x_local (B, K, N, 3) -> (M,), normalised
        models scaled back to metres."""
        kc = k if enc.slot is None else enc.slot[k]  # index into the code's part axis
        norm = enc.scale is not None
        if norm:
            sc = enc.scale[b, k]
            xin = (x_local[b, k, n] - enc.center[b, k]) / sc
        else:
            xin = x_local[b, k, n]
        with record_function(DECODER_SCOPE):
            vals = self._decode_xin(enc, xin, b, kc)
        return vals * sc[:, 0] if norm else vals

    def set_encoder_draws(self, draws: int) -> "Volume":
        """Encode each part as the mean code of `draws` fixed surface sample sets (`Partition.set_draws`; at attach:
        the checkpoint's `encoder_draws`, 1 for checkpoints without it); returns self. Encodings cached before are
        not reused (their key holds the sample set). ValueError (one line) for draws < 1."""
        self.partition.set_draws(draws)
        return self

    def set_precision(self, precision: str) -> "Volume":
        """Set the decoders' arithmetic ('full', 'bf16' or 'tf32'; see the class docstring); returns self.
        ValueError (one line, with the fix) for a precision this network or torch cannot run."""
        check_precision(precision, self.kind, model_kind(self.kind).grouped,
                        model_kind(self.kind).grouped and self.net.grouped_supported(torch.bfloat16))
        self.precision = precision
        return self

    def _decode_xin(self, enc: Encoding, xin: torch.Tensor, b: torch.Tensor, kc: torch.Tensor,
                    counts_host: list | None = None, group_sorted: bool = False) -> torch.Tensor:
        """Decoder inputs xin (M, 3) of pairs of body b (M,) and code part kc (M,) -> (M,), on the engine
        pair_decoder picks, in `precision` (bf16 always takes the grouped engine, in bfloat16). counts_host: the
        pairs per (body, code part) group, when known on the host (the tiled decoder then makes no host sync).
        group_sorted: the pairs come sorted by (b, kc) (the grouped engine then needs no sort of its own)."""
        bf16 = self.precision == "bf16"
        with matmul_precision(self.precision, xin.device):
            if not bf16 and not self._grouped_ok(xin):
                if counts_host is None:
                    return self.net.decode_pairs(xin, b, kc, enc.code)
                return self.net.decode_pairs(xin, b, kc, enc.code, counts_host=counts_host, group_sorted=group_sorted)
            if enc.grouped is None or (torch.is_grad_enabled() and enc.code.z.requires_grad
                                       and not enc.grouped[0].requires_grad):  # made without a graph: remake
                enc.grouped = self.net.grouped_matrices(enc.code)
            Bc, Kc = enc.code.z.shape[:2]
            group = b * Kc + kc
            offs = torch.cumsum(group_counts(group, Bc * Kc), 0).to(torch.int32)   # no host sync
            run = torch.bfloat16 if bf16 else None
            if group_sorted:
                return self.net.decode_grouped(xin, offs, enc.code, enc.grouped, run)
            order = torch.argsort(group, stable=True)
            vals = self.net.decode_grouped(xin[order], offs, enc.code, enc.grouped, run)
            return torch.empty_like(vals).index_put_((order,), vals)

    def _chunks(self, B: int, N: int, factor: int = 1):
        return point_ranges(N, max(1024, factor * self.chunk_elems // max(1, B * self.num_parts)))

    # ------------------------------------------------------------------ public queries
    def query_parts(self, out, points: torch.Tensor, dense: bool | None = None) -> torch.Tensor:
        """Per-part signed distance: part k's decoder where the point is in part k's padded box,
        the exact distance to that box elsewhere (positive).

        Args: out: body output (B bodies); points: (B, N, 3) or (N, 3) shared by all bodies.
        Returns: (B, K, N).
        """
        check_output(out)
        points = check_points(points, out.vertices)
        enc = self._encoding_for(out, points)
        dense = self.dense if dense is None else dense
        B, N = points.shape[:2]
        parts = [self._part_values(enc, points[:, s:e], dense)[0] for s, e in self._chunks(B, N)]
        return torch.cat(parts, dim=2) if parts else points.new_zeros(B, self.num_parts, 0)

    def query(self, out, points: torch.Tensor, dense: bool | None = None) -> torch.Tensor:
        """Signed distance to the body surface (metres, negative inside), paper eq. 4.

        Points inside at least one padded part box get min over those parts' decoders; the others
        get the analytic distance to the union of boxes (no network evaluation).
        Args: out: body output (B bodies); points: (B, N, 3) or (N, 3) shared by all bodies.
        Returns: (B, N); an empty (B, 0) for N = 0.
        """
        check_output(out)
        dense = self.dense if dense is None else dense
        if not self._lean(dense):
            points = check_points(points, out.vertices)
            return self.query_encoded(self._encoding_for(out, points), points, dense)
        given = points       # NaN and Inf are counted in the lean query's one host read: no wait of its own
        points = check_points(points, out.vertices, finite=False)
        bad = (~torch.isfinite(given)).any(dim=-1).sum()
        enc, pending = self._lean_encoding(out, points)
        return self._query(enc, points, dense, True, (bad, given.shape[:-1].numel()), pending)

    def _lean(self, dense: bool) -> bool:
        """Whether a query runs on the lean sparse path (SDF models, sparse, engine 'lean')."""
        return self.is_sdf and not dense and self.engine == "lean"

    def query_encoded(self, enc: Encoding, points: torch.Tensor, dense: bool | None = None,
                      outside: bool = True) -> torch.Tensor:
        """`query` on an explicit encoding (training encodes with fresh surface samples). points (B, N, 3) -> (B, N).
        A subset encoding must have a code for every part whose box holds a point (else those parts are
        skipped); `query` ensures it. outside=False may answer +inf instead of the box distance at points in no
        padded part box (the lean path skips those distances; see collision_loss). points may be (N, 3) (every
        body); NaN or Inf points are not checked here (no host sync): their values are NaN."""
        return self._query(enc, points, self.dense if dense is None else dense, outside, None)

    def _query(self, enc: Encoding, points: torch.Tensor, dense: bool, outside: bool, nonfinite,
               pending: dict | None = None) -> torch.Tensor:
        """query_encoded; nonfinite: None, or (count of NaN/Inf points as a device tensor, points given) for the
        lean path to read with its pairs and refuse (`query`); pending: `_lean_encoding`'s box test of these points."""
        points = check_points(points, enc.G, finite=False)  # (1, N, 3) for B > 1 bodies: refused (not body 0 alone)
        B, N = points.shape[:2]
        if self._lean(dense):
            chunks = self._lean_chunks(B, N, points.device)
            graph = (self.cuda_graph_queries and outside and len(chunks) == 1 and self.precision != "bf16"
                     and self.query_graphs.supports(enc, points))
            if graph:
                with matmul_precision(self.precision, points.device):
                    got = self.query_graphs.run(self, enc, points)
                if got is not None:
                    values, pairs, bad = got
                    if nonfinite is not None and bad:
                        raise nonfinite_points_error(int(nonfinite[0]), int(nonfinite[1]))
                    self.decoder_evaluations += pairs
                    return values
            before = self.decoder_evaluations
            res = [self._query_lean(enc, points[b0:b1, s:e], b0, outside, nonfinite if i == 0 else None,
                                    pending if len(chunks) == 1 else None)
                   for i, (b0, b1, s, e) in enumerate(chunks)]
            if graph:   # the capacity of this shape, for the next query of it
                self.query_graphs.observe(points, self.num_parts, self.decoder_evaluations - before)
            return res[0] if len(res) == 1 else assemble_chunks(res, chunks, B, N)
        res = []
        for s, e in self._chunks(B, N):
            part, inside = self._part_values(enc, points[:, s:e], dense)
            if self.is_sdf:
                implicit = torch.where(inside, part, torch.full_like(part, float("inf"))).amin(dim=1)
                res.append(torch.where(inside.any(dim=1), implicit, part.amin(dim=1)))
            else:  # COAP: max over box-masked part occupancies
                res.append(part.amax(dim=1))
        return torch.cat(res, dim=1) if res else points.new_zeros(B, 0)

    def penetration(self, values: torch.Tensor) -> torch.Tensor:
        """Per-point penetration of query values (collision_loss before the reduction): VolumetricSMPL
        ReLU(-sdf) (metres); COAP sigmoid(f) 1[f > 0] with f its logit, positive inside, i.e. the occupancy of
        the points that are inside (above the 0.5 level) and 0 elsewhere (the paper's term, supp. D.2)."""
        if self.is_sdf:
            return torch.relu(-values)
        return values * (values > self.level).to(values.dtype)

    def collision_loss(self, out, points: torch.Tensor, reduction: str = "mean") -> torch.Tensor:
        """BodyVolume.collision_loss. A point in no padded part box penetrates nothing for every kind (its SDF is
        the positive box distance, COAP's masked occupancy is 0): its value and gradient are exactly 0. So only
        the points within each body's world bounds of its boxes (boxes.near_boxes: a scene cloud around a body
        mostly lies outside them) are queried, and the box distances of those in no box are not computed."""
        check_output(out)
        points = check_points(points, out.vertices)
        frames = self._frames(out)  # for the bounds, and for the encoding when none is cached
        packed, rows, valid = near_boxes(points, *frames)
        if self._lean(self.dense):   # the box test that picks the parts to encode serves the query too
            enc, pending = self._lean_encoding(out, packed, frames)
            values = self._query(enc, packed, self.dense, False, None, pending)
        else:
            values = self.query_encoded(self._encoding_for(out, packed, frames), packed, outside=False)
        pen = torch.where(valid, self.penetration(values), 0.0)
        full = pen.new_zeros(points.shape[:2]).scatter(1, rows, pen)
        if torch.is_grad_enabled() and not full.requires_grad:  # no point near a body: gradients of exactly 0
            full = full + 0.0 * (points.sum() + frames[1].sum())
        return reduce_penetration(full, reduction)

    @torch.no_grad()
    def extract_mesh(self, out, resolution: int = 128, body_index: int = 0, padding: float = 0.05):
        """Marching cubes of the learned SDF's zero level set of one body, as a trimesh.Trimesh
        (volsmpl.volume.extraction.level_set_mesh)."""
        from volsmpl.volume.extraction import level_set_mesh
        return level_set_mesh(self, out, resolution, body_index, padding)
