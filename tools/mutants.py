"""`make mutants`: named, deliberate bugs, each of which must make at least one test fail.

Each mutant is one exact text substitution in one file of the package. It is applied to a COPY of the package
(core/ as volsmpl, apps/ as volsmpl.apps, assets linked) in a temporary folder, and the tests named for it run
against that copy (PYTHONPATH puts it before the installed work tree). The work tree is never edited. The
unmutated copy must pass the same tests first (else a "killed" mutant would prove nothing).

    python tools/mutants.py              # every mutant
    python tools/mutants.py NAME ...     # some; --list names them
Exit status 0 when every mutant is killed, 1 when one survives (or the baseline fails).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
T = "tests/"

#: name -> (file in the repository, text, its replacement, tests that must catch it)
MUTANTS = {
    # volume: code refinement carried along an optimisation
    "warm_moments_dropped": ("core/volume/warm_codes.py", 's["delta"][rows, kk], s["m1"][rows, kk], s["m2"][rows, kk] = var - zd, m1, m2',
                             's["delta"][rows, kk], s["m1"][rows, kk], s["m2"][rows, kk] = var - zd, m1 * 0, m2 * 0',
                             [T + "volume/test_warm_codes.py::test_encodings_of_a_body_that_stays_continue_one_adam_run"]),
    "warm_step_size_not_warmed_up": ("core/volume/code_refinement.py", "rise = (t / warmup).clamp(max=1.0) if warmup else 1.0",
                                     "rise = 1.0",
                                     [T + "volume/test_warm_codes.py::test_encodings_of_a_body_that_stays_continue_one_adam_run"]),
    "warm_keys_ignored": ("core/volume/warm_codes.py", "ids = torch.arange(B) if self._ids is None else self._ids",
                          "ids = torch.arange(B)",
                          [T + "volume/test_warm_codes.py::test_keys_follow_the_bodies_not_their_order"]),
    "warm_never_restarts": ("core/volume/warm_codes.py", "restart = had & (change > self.max_change)",
                            'restart = had & (change > float("inf"))',
                            [T + "volume/test_warm_codes.py::test_a_body_that_jumped_starts_afresh"]),
    "harness_opens_no_warm_scope": ("core/optim/harness.py", 'if hasattr(m, "warm_start"):', "if False:",
                                    [T + "volume/test_warm_codes.py::test_the_harness_opens_one_scope_per_run"]),
    "motion_warm_keys_by_group_position": ("apps/motion/objective.py", "ids[idx.cpu()]", "idx.cpu()",
                                           [T + "apps/motion/test_app.py::test_warm_code_refinement_keys_the_frames_by_their_rows"]),
    # body: partition and part boxes, kinematic chain, contact regions
    "boxes_padded_one_side": ("core/body/partition.py", "return center - half, center + half",
                              "return lo - 2 * (half - 0.5 * (hi - lo)), hi",
                              [T + "volume/test_references.py::test_padded_boxes_are_the_tight_boxes_grown_about_their_centre"]),
    "encoder_draws_sets_not_interleaved": ("core/body/partition.py", "f_ids = torch.cat(out_f, dim=-1).reshape(",
                                           "f_ids = torch.cat(out_f, dim=-2).reshape(",
                                           [T + "volume/test_encoder_draws.py::test_each_draw_is_a_full_set_half_tight_half_extended"]),
    "kinematics_reads_parents_from_device": ("core/body/partition.py",
                                             "chain_rotations(rodrigues(pose), (self._chain_order, self._chain_parent, self._chain_sizes))",
                                             "chain_rotations(rodrigues(pose), kinematic_levels(self.parents))",
                                             [T + "volume/test_learned.py::test_posing_and_encoding_read_no_device_values"]),
    "gpu_boxes_upper_bound_is_min": ("core/body/partition.py", 'scatter_reduce(1, idx, local, "amax", include_self=False)',
                                     'scatter_reduce(1, idx, local, "amin", include_self=False)',
                                     [T + "body/test_partition.py::test_boxes_contain_part_vertices"]),
    "chain_by_depth_wrong_parent": ("core/body/lbs.py", "glob[:, idx] = glob[:, pidx] @ rot_mats[:, idx]",
                                    "glob[:, idx] = rot_mats[:, pidx] @ rot_mats[:, idx]",
                                    [T + "body/test_model.py::test_kinematic_levels_compose_the_chain_joint_by_joint"]),
    "contact_grid_skips_lower_neighbours": ("core/body/contact_regions.py", "d = torch.arange(-1, 2, device=dev)",
                                            "d = torch.arange(0, 2, device=dev)",
                                            [T + "train/test_contact_training.py::test_contact_methods_agree"]),
    # geometry: box-centred coordinates, exact triangle queries
    "box_centred_about_the_world_origin": ("core/geometry/boxes.py", "    o = t.mean(dim=1, keepdim=True)", "    o = 0 * t.mean(dim=1, keepdim=True)",
                                           [T + "geometry/test_boxes.py::test_box_centred_coordinates_and_membership_far_from_the_origin"]),
    "mesh_batch_tests_mesh_zero": ("core/geometry/triangle_queries.py", "pi, ci = b * mask.shape[1] + i, b * self.C + c",
                                   "pi, ci = b * mask.shape[1] + i, c",
                                   [T + "geometry/test_groundtruth.py::test_mesh_query_batch_against_brute_force"]),
    # nn: part encoder, analytic box distances, pair decoders (group rows, pair layout)
    "pointnet_per_point_copy": ("core/nn/pointnet.py", "pooled = net.amax(dim=1, keepdim=True)",
                                "pooled = net", [T + "volume/test_references.py::test_pointnet_against_plain_reference"]),
    "encoder_draws_first_set_only": ("core/nn/pointnet.py", "z.reshape(B, K, draws, -1).mean(dim=2)",
                                     "z.reshape(B, K, draws, -1)[:, :, 0]",
                                     [T + "volume/test_encoder_draws.py::test_encode_parts_is_the_mean_of_each_set_encoded_alone"]),
    "box_sdf_squares_overflow": ("core/nn/analytic.py", "norm = ms[..., 0] * torch.where(pos, r2, torch.ones_like(r2)).sqrt()",
                                 "norm = qp.square().sum(-1).sqrt()", [T + "test_limits.py"]),
    "outside_distance_far_ratio_overflows": ("core/nn/analytic.py", "s[..., None]).clamp(max=1e18)", "s[..., None])",
                                            [T + "nn/test_analytic.py::test_outside_distance_gradient_stays_finite_at_rounding_edges"]),
    "outside_distance_norm_at_a_face": ("core/nn/analytic.py", "r2 = torch.where(touching, torch.ones_like(s[:, 0]), r2.amin(dim=-1))",
                                        "r2 = r2.amin(dim=-1)",
                                        [T + "nn/test_analytic.py::test_outside_distance_gradient_stays_finite_at_rounding_edges"]),
    "outside_distance_to_the_farthest_box": ("core/nn/analytic.py", "r2.amin(dim=-1))", "r2.nan_to_num(posinf=0.0).amax(dim=-1))",
                                             [T + "nn/test_analytic.py::test_outside_distance_matches_per_box_minimum",
                                              T + "volume/test_learned.py::test_far_points_skip_network_and_are_exact"]),
    "static_layout_chunk_groups_shifted": ("core/nn/pairs.py", "torch.arange(total, device=dev), right=True)",
                                           "torch.arange(total, device=dev), right=False)",
                                           [T + "volume/engine/test_query_graph.py::test_static_query_equals_the_eager_query"]),
    "group_rows_tiles_read_the_first": ("core/nn/group_rows.py", "pe = p[s:e]", "pe = p[start:start + e - s]",
                                       [T + "nn/test_nbw.py::test_decode_rows_cpu_path_equals_naive_per_point_decoder"]),
    "group_rows_unsorted_left_sorted": ("core/nn/nbw.py", "h = torch.empty_like(h).index_put_((order,), h)", "pass",
                                        [T + "nn/test_nbw.py::test_decode_rows_cpu_path_equals_naive_per_point_decoder"]),
    "group_rows_skip_reads_h_only": ("core/nn/group_rows.py", "h = h.addmm_(pe, Wp[l][i])", "h = h",
                                     [T + "nn/test_nbw.py::test_decode_rows_cpu_path_equals_naive_per_point_decoder"]),
    # volume/engine: lean query, CUDA-graph encode and static query
    "decoder_counts_groups_again": ("core/volume/engine/lean_query.py",
                                    "vals = self._decode_xin(enc, xin, b + b0, kc, counts_host, group_sorted=True)",
                                    "vals = self._decode_xin(enc, xin, b + b0, kc, group_sorted=True)",
                                    [T + "volume/test_learned.py::test_lean_query_makes_one_host_sync_per_chunk"]),
    "gpu_lean_chunks_follow_chunk_elems": ("core/volume/engine/lean_query.py", "if cpu else self.gpu_chunk_elems", "if cpu else self.chunk_elems",
                                           [T + "volume/test_learned.py::test_lean_chunks_one_body_per_chunk_on_the_cpu"]),
    "lean_pairs_in_point_order": ("core/volume/engine/lean_query.py",
                                  "b, k, n = torch.nonzero_static(by_part, size=n_pairs).unbind(1)",
                                  "b, n, k = torch.nonzero_static(inside, size=n_pairs).unbind(1)",
                                  [T + "volume/test_learned.py::test_engines_equal_dense_values_and_gradients"]),
    "replayed_encode_shares_its_outputs": ("core/volume/engine/encode_graph.py", "return map_tensors(torch.Tensor.clone, self.result)",
                                           "return self.result",
                                           [T + "volume/engine/test_encode_graph.py::test_replay_equals_eager_and_owns_its_outputs"]),
    "graph_key_without_settings": ("core/volume/engine/encode_graph.py", "storage, settings_key(modules), torch", "storage, (), torch",
                                   [T + "volume/engine/test_encode_graph.py::test_settings_batch_and_autograd_decide_the_graph"]),
    "graph_key_without_storage": ("core/volume/engine/encode_graph.py", "(inputs, str(out.vertices.device), storage,",
                                  "(inputs, str(out.vertices.device), (),",
                                  [T + "volume/engine/test_encode_graph.py::test_weights_edited_in_place_are_read_replaced_ones_recaptured"]),
    "static_query_skips_box_distances": ("core/volume/engine/query_graph.py", "values = torch.where(free, box, best)", "values = best",
                                         [T + "volume/engine/test_query_graph.py::test_static_query_equals_the_eager_query"]),
    "query_graph_ignores_overflow": ("core/volume/engine/query_graph.py", "        if pairs > cap:", "        if False:",
                                     [T + "volume/engine/test_query_graph.py::test_overflow_answers_eagerly_and_raises_the_capacity"]),
    "frozen_configs_left_out_of_the_graph_key": ("core/volume/engine/encode_graph.py", "_Same(value) if kind.__dataclass_params__.frozen else repr(value)",
                                                 "None if kind.__dataclass_params__.frozen else repr(value)",
                                                 [T + "volume/engine/test_encode_graph.py::test_settings_batch_and_autograd_decide_the_graph"]),
    # volume: query, encoding cache and fingerprints, collision and self-penetration, attach, code refinement
    "refine_normal_flipped": ("core/volume/code_refinement.py", "x = torch.cat([s, s], dim=2) + t[..., None]",
                              "x = torch.cat([s, s], dim=2) - t[..., None]",
                              [T + "volume/test_code_refinement.py::test_fitting_points_lie_at_their_targets_from_the_posed_mesh"]),
    "refine_offsets_not_per_part": ("core/volume/code_refinement.py", "t = (t if parts is None else t[parts.cpu()])",
                                    "t = (t if parts is None else t[:len(parts)])",
                                    [T + "volume/test_code_refinement.py::test_refining_some_parts_gives_the_codes_of_refining_all"]),
    "refine_not_in_cache_key": ("core/volume/encoding.py", '("refine_steps", int(self.refine_steps)),', "",
                                [T + "volume/test_code_refinement.py::test_changing_the_setting_re_encodes"]),
    "refine_correction_dropped": ("core/volume/code_refinement.py", "return z + (var - z.detach())", "return z",
                                  [T + "volume/test_code_refinement.py::test_refined_codes_are_closer_to_the_exact_distance",
                                   T + "volume/test_code_refinement.py::test_coap_refinement_fits_its_occupancy"]),
    "collision_sum_is_mean": ("core/volume/collision.py", "return pen.sum(dim=1)", "return pen.mean(dim=1)",
                              [T + "volume/test_references.py::test_collision_loss_reductions_against_relu_of_query"]),
    "query_min_over_all_parts": ("core/volume/learned.py",
                                 'implicit = torch.where(inside, part, torch.full_like(part, float("inf"))).amin(dim=1)',
                                 "implicit = part.amin(dim=1)", [T + "volume/test_references.py::test_query_is_min_over_the_parts_whose_box_holds_the_point"]),
    "selfpen_sign_flipped": ("core/volume/self_penetration.py", "torch.sigmoid(-part / tau)", "torch.sigmoid(part / tau)",
                             [T + "volume/test_references.py::test_selfpen_penalty_by_hand"]),
    "cache_ignores_output_content": ("core/volume/encoding.py", "cached[0] is self and cached[1].key == key else None", "cached[0] is self else None",
                                     [T + "volume/test_encoding.py"]),
    "cache_weights_by_version": ("core/volume/fingerprint.py", "return fingerprint([*module.parameters(), *module.buffers()])",
                                 "return tuple((t.data_ptr(), t._version) for t in (*module.parameters(), *module.buffers()))",
                                 [T + "volume/test_encoding.py"]),
    "pretrained_not_frozen": ("core/volume/attach.py", "volume.requires_grad_(not pretrained if trainable is None else bool(trainable))",
                              "volume.requires_grad_(True)", [T + "volume/test_frozen.py"]),
    "volume_stays_behind": ("core/volume/attach.py", 'object.__setattr__(body, "_apply", types.MethodType(_apply_with_volume, body))',
                            "pass", [T + "test_cuda_paths.py::test_volume_moves_with_its_body"]),
    "cache_serves_graph_free_encoding": ("core/volume/encoding.py", "if found is not None and not found.graph and torch.is_grad_enabled()",
                                         "if False and not found.graph and torch.is_grad_enabled()",
                                         [T + "volume/test_encoding.py::test_encoding_made_without_graph_is_not_served_to_a_gradient"]),
    "selfpen_cached_codes_keep_graph": ("core/volume/learned.py", "        elif not code_grad:\n", "        elif False:\n",
                                        [T + "volume/test_learned.py::test_selfpen_rigid_code_gradient"]),
    "float64_body_float32_volume": ("core/volume/attach.py", "return dtype if dtype is not None and dtype.is_floating_point else None",
                                    "return None", [T + "volume/test_learned.py::test_attach_to_a_float64_body_gives_a_float64_volume"]),
    "query_drops_nonfinite_count": ("core/volume/learned.py", "dense, True, (bad, given.shape[:-1].numel()), pending)", "dense, True, None, pending)",
                                    [T + "volume/test_learned.py::test_empty_and_bad_points"]),
    "fingerprint_every_step": ("core/volume/encoding.py",
                               "if (cached is None or cached[0] is not self) and not (constant and self._last is not None):",
                               "if False:", [T + "volume/test_encoding.py::test_fingerprint_only_when_a_cached_encoding_could_answer"]),
    "replay_path_makes_eager_frames": ("core/volume/encoding.py", "if enc is None and self._replays(out):", "if False:",
                                       [T + "volume/engine/test_encode_graph.py::test_query_on_the_replay_path_makes_no_eager_frames"]),
    # train: config checks, run folder, resume
    "train_config_unchecked": ("core/train/config.py", "        check_numbers(self)\n", "", [T + "test_limits.py"]),
    "run_folder_unlocked": ("core/train/loop.py", 'with exclusive_folder(out_dir, "volsmpl train") if rank == 0 else contextlib.nullcontext():',
                            "with contextlib.nullcontext():", [T + "train/test_faults.py::test_second_writer_of_a_run_folder_is_refused"]),
    "run_config_written_in_place": ("core/train/loop.py", 'write_atomic(out_dir / "config.json", json.dumps(cfg.to_dict(), indent=1))',
                                    '(out_dir / "config.json").write_text(json.dumps(cfg.to_dict(), indent=1))',
                                    [T + "train/test_faults.py::test_killed_while_writing_the_run_config_resumes"]),
    "resume_copied_checkpoint_on_defaults": ("core/train/loop.py", '            return _checkpoint_train_config(ck / "model")\n',
                                             "            return {}\n",
                                             [T + "train/test_loop.py::test_cli_resume_and_init_take_the_checkpoints_training_config"]),
    # evaluation: validation and per-part points
    "eval_sigma_x1.3": ("core/evaluation/points.py", "cfg.bbox_padding,\n                        cfg.surface_sigma)",
                        "cfg.bbox_padding,\n                        cfg.surface_sigma * 1.3)",
                        [T + "volume/test_references.py::test_evaluation_near_surface_spread"]),
    "part_points_sigma_x1.3": ("core/evaluation/points.py", "dtype=torch.float64) * surface_sigma",
                               "dtype=torch.float64) * surface_sigma * 1.3",
                               [T + "evaluation/test_points.py::test_offsets_are_gaussian_with_the_given_sigma"]),
    "part_points_extended_faces": ("core/evaluation/points.py", "for ids in part.tight_face_ids", "for ids in part.extended_face_ids",
                                   [T + "evaluation/test_points.py::test_surface_blocks_lie_on_their_parts_own_faces"]),
    # io: checkpoints and the case store
    "checkpoint_weights_unverified": ("core/io/checkpoint.py", 'if digests is not None and weights_digest(state_dict) != digests["weights"]:',
                                      "if False:", [T + "io/test_checkpoint.py"]),
    "checkpoint_config_unverified": ("core/io/checkpoint.py", 'elif digests["config"] != config_digest(config):', "elif False:",
                                     [T + "io/test_checkpoint.py"]),
    "checkpoint_nan_accepted": ("core/io/checkpoint.py", "bad = _non_finite(state_dict)", "bad = None", [T + "io/test_checkpoint.py"]),
    "job_key_abbreviated_arrays": ("core/io/case_store.py", "separators=(\",\", \":\"), default=_exact)", "separators=(\",\", \":\"), default=str)",
                                   [T + "io/test_case_store.py::test_key_sees_every_element_of_large_arrays"]),
    # report: a result's producer
    "report_producer_app_only": ("core/report/build.py", "return producer_closure(section.producer + _BODY_DATA, git.root)",
                                 "return section.producer", [T + "report/test_build.py::test_stale_when_core_code_the_app_imports_changed"]),
    "report_tables_unbounded": ("core/report/sections.py", "    more = extra[max(0, MAX_COLUMNS - 1 - len(cols)):]",
                                "    more = []", [T + "report/test_build.py::test_wide_summaries_keep_the_paper_columns_first_and_tables_at_most_ten_columns"]),
    "report_takes_another_apps_result": ("core/report/build.py", "    if isinstance(app, str) and app != key:",
                                         "    if False:",
                                         [T + "report/test_build.py::test_a_result_of_another_app_is_refused_for_a_section"]),
    "check_labels_keep_the_kind_key": ("core/report/result_check.py", "walk(v, case, path if grouped else path + (str(k),))",
                                       "walk(v, case, path + (str(k),))",
                                       [T + "report/test_result_check.py::test_records_grouped_by_the_kind_they_name_compare_with_the_same_records_listed_flat"]),
    # runtime: the resource meter
    "meter_peak_from_missing_rss": ("core/runtime/meter.py", "            elif rss_bytes() < 0:", "            elif False:",
                                    [T + "runtime/test_meter.py::test_cpu_meter_without_proc_reports_the_rise_of_ru_maxrss"]),
    # scene: generated rooms' cache
    "room_cache_by_number_only": ("core/scene/rooms.py", 'code_version(ROOM_VERSION, "volsmpl.scene")', "ROOM_VERSION",
                                  [T + "scene/test_cache.py::test_code_version_follows_the_generators_source"]),
    # cli: device checks
    "device_unchecked": ("core/cli.py", "            check_device(args.device)\n", "", [T + "test_cuda_paths.py::test_device_cuda_without_cuda_is_one_line",
                                                                                   T + "test_cuda_paths.py::test_check_device_names"]),
    # apps: the shared options and case records
    "threads_zero_accepted": ("apps/table.py", "or threads < 1:", "or threads < 0:",
                              [T + "apps/selfpen/test_app.py::test_cli_case_and_checkpoint_mistakes_stop_before_any_work"]),
    "case_records_ignore_the_settings": ("apps/table.py", "        key = self.key(spec, volume)", "        key = self.key({}, volume)",
                                         [T + "apps/selfpen/test_app.py::test_cli_resume_reuses_finished_repairs_and_refits_changed_settings"]),
    "egohmr_resume_key_of_every_guide": ("apps/egohmr/run.py", 'if k not in ("scales", "models", "checkpoints")}', "}",
                                         [T + "apps/egohmr/test_app.py::test_resume_reuses_each_finished_guide_and_samples_again_on_other_settings"]),
    # apps: checks of a user's options, data and output folder
    "options_of_other_modes_ignored": ("apps/checks.py", "    if extra:\n        flags", "    if False:\n        flags",
                                       [T + "apps/selfpen/test_user_data.py::test_tune_refuses_the_run_options"]),
    "nan_option_accepted": ("apps/checks.py", "    bad = not math.isfinite(x)", "    bad = False",
                            [T + "apps/selfpen/test_user_data.py::test_wrong_options_are_refused_in_one_line"]),
    "results_of_another_app_replaced": ("apps/checks.py", "        if other is not None and other != app:",
                                        "        if False:",
                                        [T + "apps/selfpen/test_user_data.py::test_an_output_folder_of_another_app_or_in_use_is_refused"]),
    "results_json_with_nan": ("apps/checks.py", "        return obj if math.isfinite(obj) else None", "        return obj",
                              [T + "apps/test_checks.py::test_results_json_is_standard_json"]),
    "selfpen_results_only_at_the_end": ("apps/selfpen/cli.py",
                                        "        path, flagged = _write(args.out, config, per_model, figures, cfg.device)",
                                        "        path, flagged = (_write(args.out, config, per_model, figures, cfg.device)"
                                        " if case is cases[-1] else (None, []))",
                                        [T + "apps/selfpen/test_user_data.py::test_a_stopped_run_keeps_its_finished_cases"]),
    "selfpen_worse_repair_not_flagged": ("apps/selfpen/optimize.py",
                                         "    elif res.collisions_after > res.collisions_before:",
                                         "    elif res.collisions_after > 2 * res.collisions_before + 10 ** 9:",
                                         [T + "apps/selfpen/test_app.py::test_repair_loop_stops_when_no_points_remain"]),
    "selfpen_pose_in_degrees_accepted": ("apps/selfpen/cases.py", "        if angles.max() > MAX_ANGLE:",
                                         "        if angles.max() > 100 * MAX_ANGLE:",
                                         [T + "apps/selfpen/test_user_data.py::test_a_pose_in_degrees_or_betas_of_another_scale_are_refused"]),
    "hoi_units_unchecked": ("apps/hoi/plausibility.py", "    if not 1 / L[\"size_refuse\"] <= ratio <= L[\"size_refuse\"]:",
                            "    if False:", [T + "apps/hoi/test_plausibility.py::test_wrong_units_are_refused_naming_the_right_ones"]),
    "hoi_units_hint_of_the_declared_unit": ("apps/hoi/plausibility.py", "abs(math.log(raw * _UNITS[u] *",
                                            "abs(math.log(raw * _UNITS[case.units] *",
                                            [T + "apps/hoi/test_plausibility.py::test_wrong_units_are_refused_naming_the_right_ones"]),
    "hoi_far_object_accepted": ("apps/hoi/plausibility.py", "    if gap > L[\"gap_refuse_m\"]:", "    if gap > 1e9:",
                                [T + "apps/hoi/test_plausibility.py::test_an_object_far_from_its_origin_or_from_the_body_is_refused"]),
    "hoi_principal_point_unchecked": ("apps/hoi/plausibility.py", "    if not (0 <= cx <= W and 0 <= cy <= H):",
                                      "    if not (0 <= cx <= 10 * W and 0 <= cy <= 10 * H):",
                                      [T + "apps/hoi/test_plausibility.py::test_a_camera_for_another_image_is_refused"]),
    "hoi_lost_object_judged_converged": ("apps/hoi/plausibility.py",
                                         "    if ga > L[\"lost_m\"] and ga > gb + L[\"lost_more_m\"]:",
                                         "    if ga > L[\"lost_m\"] * 1e6:",
                                         [T + "apps/hoi/test_plausibility.py::test_judge_fit_on_hand_made_measures"]),
    "hoi_worse_collision_judged_converged": ("apps/hoi/plausibility.py",
                                             "    if ca > cb + L[\"worse_collision_pct\"]:", "    if ca > cb + 100:",
                                             [T + "apps/hoi/test_plausibility.py::test_judge_fit_on_hand_made_measures"]),
    # optim: a problem that diverges
    "diverged_problem_keeps_its_broken_values": ("core/optim/harness.py", "            p[rows] = before[n][rows]",
                                                 "            pass",
                                                 [T + "optim/test_optim.py::test_a_problem_that_diverges_stops_and_keeps_its_last_finite_values"]),
    "diverged_when_the_loss_is_not_finite_missed": ("core/optim/harness.py",
                                                    "lost = active & ~torch.isfinite(ev.total)",
                                                    "lost = active & torch.isnan(ev.total) & False",
                                                    [T + "optim/test_optim.py::test_a_problem_that_diverges_stops_and_keeps_its_last_finite_values"]),
    # apps/egohmr: a user's frame and scene, the options per mode, the sample's status
    "egohmr_intrinsics_unchecked": ("apps/egohmr/userframe.py", "    if not (CENTRE[0] * W <= cx <= CENTRE[1] * W and CENTRE[0] * H <= cy <= CENTRE[1] * H):", "    if False:",
                                    [T + "apps/egohmr/test_user_checks.py::test_camera_matrix_of_another_image_size_is_refused_naming_k"]),
    "egohmr_principal_point_off_centre_unwarned": ("apps/egohmr/user_checks.py",
                                                   "    if abs(cx - W / 2) > PP_WARN * W or abs(cy - H / 2) > PP_WARN * H:",
                                                   "    if False:",
                                                   [T + "apps/egohmr/test_user_checks.py::test_a_principal_point_off_the_centre_is_warned_about"]),
    "egohmr_focal_length_unchecked": ("apps/egohmr/user_checks.py", "    if not FOV_REFUSE_DEG[0] <= fov <= FOV_REFUSE_DEG[1]:", "    if False:",
                                      [T + "apps/egohmr/test_user_checks.py::test_camera_matrix_of_another_image_size_is_refused_naming_k"]),
    "egohmr_units_unchecked": ("apps/egohmr/user_checks.py", "    if not EXTENT_REFUSE[0] <= ext <= EXTENT_REFUSE[1]:", "    if False:",
                               [T + "apps/egohmr/test_user_checks.py::test_scene_in_millimetres_read_as_metres_is_refused_naming_units"]),
    "egohmr_up_unchecked": ("apps/egohmr/user_checks.py", "    if ang[alt] <= UP_TOL_DEG:", "    if False:",
                            [T + "apps/egohmr/test_user_checks.py::test_scene_turned_z_up_is_refused_without_up_z"]),
    "egohmr_floor_without_walls": ("core/scene/floor.py", "    if a < FLOOR_MIN or other > WALLS_MAX or (wpos + wneg).min() < FLAT_SIDES:",
                                   "    if a < FLOOR_MIN:", [T + "apps/egohmr/test_user_checks.py::test_floor_estimate_needs_a_room_around_it"]),
    "egohmr_negative_scale_accepted": ("apps/egohmr/options.py", 'given[g] = number(v, f"--scale {g}", lo=0,',
                                       'given[g] = number(v, f"--scale {g}", lo=None,', [T + "apps/egohmr/test_user_checks.py::test_numbers_out_of_range_are_refused"]),
    "egohmr_budget_unchecked": ("apps/egohmr/options.py", 'number(args.budget_mb, "--budget-mb", lo=0, lo_open=True,',
                                'number(args.budget_mb, "--budget-mb", lo=None, lo_open=True,', [T + "apps/egohmr/test_user_checks.py::test_numbers_out_of_range_are_refused"]),
    "egohmr_mode_options_unchecked": ("apps/egohmr/options.py", "    applies(args, mode, uses)", "    pass",
                                      [T + "apps/egohmr/test_user_checks.py::test_options_the_mode_does_not_read_are_refused"]),
    "egohmr_tuned_falls_back_to_the_paper": ("apps/egohmr/options.py", '    need = [g for g in guides if g != "none" and g not in given]',
                                             '    need = [g for g in guides if g in best and g not in given]',
                                             [T + "apps/egohmr/test_user_checks.py::test_factors_steps_and_tuned_files_are_checked"]),
    "egohmr_out_not_claimed": ("apps/egohmr/cli.py", '    with claim_out(args.out, "egohmr"):', "    if True:",
                               [T + "apps/egohmr/test_user_checks.py::test_an_out_folder_of_another_app_is_refused"]),
    "egohmr_status_always_ok": ("apps/egohmr/status.py", '    if not rec.get("finite", True):',
                                '    return "ok", ""\n    if not rec.get("finite", True):', [T + "apps/egohmr/test_user_checks.py::test_judge_of_hand_made_records"]),
    "egohmr_joint_limits_lower_bound_only": ("apps/egohmr/status.py", "over = np.maximum(np.maximum(lim[..., 0] - e, e - lim[..., 1]), 0.0)",
                                             "over = np.maximum(lim[..., 0] - e, 0.0)", [T + "apps/egohmr/test_user_checks.py::test_joint_limit_excess_of_hand_made_poses"]),
    "egohmr_reprojection_counts_undetected": ("apps/egohmr/status.py", "    seen = k[..., 2] > 0", "    seen = k[..., 2] >= 0",
                                              [T + "apps/egohmr/test_user_checks.py::test_reprojection_error_of_hand_made_joints"]),
    "egohmr_penetration_depth_by_nearest_vertex": ("apps/egohmr/status.py",
                                                   "out[b] = float((BodyMesh(v, f).distances(cand) > DEEP_M).sum()) / points.shape[1]",
                                                   "out[b] = float(len(cand)) / points.shape[1]",
                                                   [T + "apps/egohmr/test_user_checks.py::test_deep_ratio_and_diverged_pose_of_a_hand_made_body"]),
    "egohmr_diverged_row_averaged": ("apps/egohmr/evaluate.py", '    if row["n_diverged"]:', "    if False:",
                                     [T + "apps/egohmr/test_app.py::test_a_diverged_sample_is_flagged_not_fatal"]),
    # apps/motion: a user's scene, the options, the walk's status, the output
    "motion_floor_axis_the_least_floor_like": ("core/scene/floor.py", "order = sorted(AXES, key=lambda a: -scores[a])",
                                               "order = sorted(AXES, key=lambda a: scores[a])",
                                               [T + "apps/motion/test_user_scene.py::test_floor_axis_of_a_hand_made_room"]),
    "motion_floor_axis_ignores_the_opposite_slab": ("core/scene/floor.py", "max(low - 0.5 * high, 0.0)", "low",
                                                    [T + "apps/motion/test_user_scene.py::test_floor_axis_with_a_ceiling_and_an_unclear_corridor"]),
    "motion_scene_units_unchecked": ("apps/motion/scene_checks.py", "    if big > MAX_SPAN_M or big < MIN_SPAN_M:", "    if False:",
                                     [T + "apps/motion/test_user_scene.py::test_a_room_in_millimetres_read_as_metres_is_refused_naming_the_units"]),
    "motion_up_disagreement_only_warned": ("apps/motion/scene_checks.py", "if est.clear and floor_y is None:", "if False:",
                                           [T + "apps/motion/test_user_scene.py::test_the_generated_room_turned_z_up"]),
    "pickled_scan_unnamed": ("core/scene/scan.py", '        if "allow_pickle" in str(e):', "        if False:",
                             [T + "apps/motion/test_user_scene.py::test_unreadable_scene_files_are_one_line_naming_the_file_and_the_formats"]),
    "motion_scene_name_not_file_safe": ("apps/motion/scenes.py", "MotionScene(safe_name(Path(path).stem)", "MotionScene(Path(path).stem",
                                        [T + "apps/motion/test_user_scene.py::test_a_scene_name_with_spaces_or_accents_is_made_file_safe"]),
    "motion_mode_options_unchecked": ("apps/motion/options.py", "    applies(args, mode, USES[mode])\n", "",
                                      [T + "apps/motion/test_user_scene.py::test_cli_refuses_options_a_mode_does_not_read_and_bad_numbers_before_any_work"]),
    "motion_lr_unchecked": ("apps/motion/options.py", 'number(args.lr, "--lr", lo=0, lo_open=True,', 'dict(lo=0, lo_open=True,',
                            [T + "apps/motion/test_user_scene.py::test_cli_refuses_options_a_mode_does_not_read_and_bad_numbers_before_any_work"]),
    "motion_out_unclaimed": ("apps/motion/cli.py", 'with claim_out(args.out, "motion"):', "if True:",
                             [T + "apps/motion/test_user_scene.py::test_cli_refuses_an_out_holding_another_apps_results"]),
    "motion_status_always_reached": ("apps/motion/status.py", "problems = _problems(rec)", "problems = []",
                                     [T + "apps/motion/test_status.py::test_status_of_hand_made_records"]),
    "motion_colliding_by_frames_only": ("apps/motion/status.py", "if pct > COLLIDING_FRAMES_PCT or depth > COLLIDING_CM:",
                                        "if pct > COLLIDING_FRAMES_PCT:", [T + "apps/motion/test_status.py::test_status_of_hand_made_records"]),
    "motion_walk_through_an_obstacle_unjudged": ("apps/motion/status.py", "if deepest > DEEP_CM and pct >= DEEP_FRAMES_PCT",
                                                 "if deepest > 10 * DEEP_CM and pct >= DEEP_FRAMES_PCT",
                                                 [T + "apps/motion/test_status.py::test_status_of_hand_made_records"]),
    "motion_worse_than_start_unjudged": ("apps/motion/status.py", "c1 > WORSE_RATIO * c0 + WORSE_ABS", "False",
                                         [T + "apps/motion/test_status.py::test_status_of_hand_made_records"]),
    "motion_harness_divergence_unjudged": ("apps/motion/status.py", 'if m.get("stop") == "diverged":', "if False:",
                                           [T + "apps/motion/test_status.py::test_status_of_hand_made_records"]),
    "motion_nan_walk_ends_the_run": ("apps/motion/cli.py", 'if "NaN or Inf" not in str(e):', "if True:",
                                     [T + "apps/motion/test_status.py::test_my_room_runs_end_to_end_and_a_diverged_walk_is_flagged"]),
    "motion_results_only_at_the_end": ("apps/motion/cli.py", "                    save_partial()\n", "",
                                       [T + "apps/motion/test_status.py::test_my_room_runs_end_to_end_and_a_diverged_walk_is_flagged"]),
    # apps/motion: the table's paired differences
    "paired_by_list_order": ("apps/motion/stats.py", "common = sorted(set(seqs[a]) & set(seqs[b]))",
                             "common = list(seqs[a])[:min(len(seqs[a]), len(seqs[b]))]; seqs = {a: dict(zip(common, "
                             "seqs[a].values())), b: dict(zip(common, seqs[b].values()))}",
                             [T + "apps/motion/test_stats.py::test_pairs_match_sequences_not_list_order"]),
    "paired_interval_of_the_wrong_level": ("apps/stats.py", "confidence_level=confidence,",
                                           "confidence_level=confidence / 2,",
                                           [T + "apps/test_stats.py::test_interval_matches_normal_theory_on_a_large_sample"]),
    # the apps' outputs: bodies, meshes and figures a user takes away
    "selfpen_after_mesh_is_the_start": ("apps/selfpen/bodies.py", 'for what, output in (("before", before), ("after", after)):',
                                        'for what, output in (("before", before), ("after", before)):',
                                        [T + "apps/selfpen/test_outputs.py::test_a_users_case_gives_its_repaired_body_and_meshes_in_the_record"]),
    "selfpen_meshes_always": ("apps/selfpen/bodies.py", "    return bool(save_meshes) or Path(case_file).resolve() != CASES_FILE.resolve()",
                              "    return True", [T + "apps/selfpen/test_outputs.py::test_the_shipped_table_writes_meshes_only_with_save_meshes"]),
    "selfpen_resumed_meshes_stale": ("apps/selfpen/cli.py", "            made = take_away(body, case, r.body_pose, m, mesh_out)",
                                     "            made = take_away(body, case, r.body_pose, m, None if reused else mesh_out)",
                                     [T + "apps/selfpen/test_outputs.py::test_a_resumed_run_makes_its_meshes_again_from_the_record"]),
    "selfpen_figure_hides_collisions": ("apps/selfpen/figures.py", "    marked[np.asarray(pairs, np.int64).ravel()] = True", "    pass",
                                        [T + "apps/selfpen/test_outputs.py::test_the_figure_shows_the_colliding_triangles_in_red"]),
    "scan_cloud_keeps_farthest_point_per_voxel": ("core/scene/scan.py", "order = np.lexsort((off, cell[:, 2]", "order = np.lexsort((-off, cell[:, 2]",
                                                  [T + "scene/test_scan.py::test_cloud_thinned_to_one_point_per_voxel_nearest_its_centre"]),
    "scan_mesh_whole_faces_counted": ("core/scene/scan.py", "            big = crosses & (", "            big = False & (",
                                      [T + "scene/test_scan.py::test_mesh_points_at_the_spacing_inside_the_box"]),
    "floor_level_lowest_slab": ("core/scene/floor.py", "    centre = float(edges[int(counts.argmax())])",
                                "    centre = float(edges[int(np.flatnonzero(counts).min())])",
                                [T + "scene/test_scan.py::test_floor_level_ignores_strays_below_the_floor"]),
    "outputs_up_axis_not_turned_back": ("core/scene/scan.py", "        return np.stack([points[:, 0], -points[:, 2], points[:, 1]], 1)",
                                        "        return np.stack([points[:, 0], points[:, 2], points[:, 1]], 1)",
                                        [T + "apps/test_outputs.py::test_from_y_up_inverts_to_y_up"]),
    # self-intersection repairs within the anatomy
    "limits_no_wrap": ("core/body/limits.py", "    return mid + torch.remainder(e - mid + np.pi, 2 * np.pi) - np.pi", "    return e",
                       [T + "body/test_limits.py::test_an_angle_past_half_a_turn_is_the_same_turn"]),
    "limits_clamp_moves_every_joint": ("core/body/limits.py", "    return torch.where(out_of[..., None], aa, pose).reshape(B, 69)",
                                       "    return aa.reshape(B, 69)",
                                       [T + "body/test_limits.py::test_clamp_turns_only_the_joints_beyond_their_limits_to_the_clamped_angles"]),
    "contact_joints_include_the_trunk": ("core/body/limits.py", "        for j in (limbs or joints):", "        for j in joints:",
                                         [T + "body/test_limits.py::test_contact_joints_of_an_arm_against_the_chest_and_a_hand_against_a_thigh"]),
    "harness_project_ignored": ("core/optim/harness.py", "            p.copy_(torch.where(active.reshape(-1, *[1] * (p.ndim - 1)), moved, p))",
                                "            pass", [T + "optim/test_optim.py::test_project_is_a_hard_bound_after_every_update"]),
    "selfpen_holds_nothing": ("apps/selfpen/optimize.py", "    idx = torch.as_tensor(np.flatnonzero(np.repeat(free, 3)), device=dev)",
                              "    idx = torch.arange(69, device=dev)",
                              [T + "apps/selfpen/test_limits.py::test_an_arm_cross_is_repaired_by_the_arms_alone_within_the_limits"]),
    "selfpen_beyond_limits_not_flagged": ("apps/selfpen/optimize.py", "    elif res.limits_after:", "    elif False:",
                                          [T + "apps/selfpen/test_limits.py::test_without_the_bounds_the_spine_folds_and_the_repair_is_flagged"]),
    "egohmr_cube_box_not_turned_to_the_world": ("apps/egohmr/user_scene.py", "    world = (corners - t) @ R          # R^T (c - t), row vectors",
                                                "    world = corners",
                                                [T + "apps/egohmr/test_user_scene.py::test_points_in_the_cube_are_area_over_spacing_squared_on_any_size"]),
    "egohmr_body_pelvis_in_camera_frame": ("apps/egohmr/bodies.py", "        pelvis = (pelvis - t) @ R", "        pelvis = pelvis - t",
                                           [T + "apps/egohmr/test_examples.py::test_record_params_rebuild_the_mesh_file_in_the_scan_frame"]),
    "egohmr_table_meshes_always": ("apps/egohmr/run.py", "            if args.save_meshes and v is not None:", "            if v is not None:",
                                   [T + "apps/egohmr/test_table_bodies.py::test_meshes_only_with_save_meshes_made_from_the_record"]),
    "egohmr_figure_without_keypoints": ("apps/egohmr/figures.py", "        draw_confident_keypoints(img, frame.keypoints * s, frame.conf)\n", "",
                                        [T + "apps/egohmr/test_examples.py::test_example_writes_bodies_meshes_and_figure"]),
    # hoi on a user's own data: make-case, the object's budget, the outputs and figures
    "hoi_table_meshes_always": ("apps/hoi/cli.py", '    save = args.action == "fit" or args.save_meshes  # a user\'s own case: its meshes always',
                                "    save = True",
                                [T + "apps/hoi/test_outputs.py::test_a_table_run_writes_meshes_only_with_save_meshes_and_resume_keeps_them"]),
    "hoi_side_view_along_the_front": ("apps/hoi/views.py", "        return np.array([f[2], 0.0, -f[0]]) * (self.object_side() if side is None else side)",
                                      "        return np.array([f[0], 0.0, f[2]]) * (self.object_side() if side is None else side)",
                                      [T + "apps/hoi/test_outputs.py::test_views_frame_the_body_and_the_side_view_looks_across_the_upright_body"]),
    "hoi_record_first_stage_is_the_fit": ("apps/hoi/fit.py", '            "first_stage": case.init["object"].to_dict()}',
                                          '            "first_stage": fitted.to_dict()}',
                                          [T + "apps/hoi/test_outputs.py::test_records_hold_the_fitted_body_and_object_and_rebuild_the_mesh_files"]),
    "hoi_region_budget_ignored": ("apps/hoi/problem.py", "    if len(f) <= budget:\n        return v[f]", "    if True:\n        return v[f]",
                                  [T + "apps/hoi/test_losses.py::test_the_terms_see_a_fixed_budget_whatever_the_mesh"]),
    "hoi_penetration_reads_every_vertex": ("apps/hoi/problem.py", "m.vertices if len(m.vertices) <= PEN_POINTS else", "m.vertices if True else",
                                           [T + "apps/hoi/test_losses.py::test_the_terms_see_a_fixed_budget_whatever_the_mesh"]),
    "hoi_make_case_silhouette_xor": ("apps/hoi/case_geometry.py", "        cv2.fillConvexPoly(m, tri, 1, lineType=cv2.LINE_8, shift=4)",
                                     "        cv2.fillPoly(m, list(np.round(uv[faces] * 16).astype(np.int32)), 1, lineType=cv2.LINE_8, shift=4)",
                                     [T + "apps/hoi/test_make_case.py::test_body_keypoints_silhouette_and_regions_against_references"]),
    "hoi_make_case_body_turned_about_origin": ("apps/hoi/make_case.py", '    return Similarity(1.0, R, root - R @ root + body_in["transl"])',
                                               '    return Similarity(1.0, R, body_in["transl"])',
                                               [T + "apps/hoi/test_make_case.py::test_body_keypoints_silhouette_and_regions_against_references"]),
    "hoi_mask_depth_from_largest_side": ("apps/hoi/case_geometry.py", "/ np.hypot(w_px, h_px))", "/ max(w_px, h_px))",
                                         [T + "apps/hoi/test_make_case.py::test_mask_placement_pnp_and_a_named_template_region"]),
    "hoi_case_always_version_2": ("apps/hoi/case.py", "    version = VERSION if case.size_m is not None or case.regions else 1", "    version = VERSION",
                                  [T + "apps/hoi/test_make_case.py::test_case_format_reads_version_1_and_checks_regions"]),
    "hoi_size_from_the_templates_only": ("apps/hoi/plausibility.py", "    size = object_size_m(case.category, case.size_m)",
                                         "    size = object_size_m(case.category)",
                                         [T + "apps/hoi/test_make_case.py::test_a_case_of_any_category_with_its_size_fits"]),
    "hoi_silhouette_one_fillpoly": ("apps/hoi/case_geometry.py",
                                    "    for tri in np.round(np.clip(uv[faces], -1e5, 1e5) * 16).astype(np.int32):\n        cv2.fillConvexPoly(m, tri, 1, lineType=cv2.LINE_8, shift=4)",
                                    "    cv2.fillPoly(m, list(np.round(np.clip(uv[faces], -1e5, 1e5) * 16).astype(np.int32)), 1, lineType=cv2.LINE_8, shift=4)",
                                    [T + "apps/hoi/test_database.py::test_the_silhouette_of_a_closed_mesh_is_its_whole_projection"]),
    "motion_corridor_without_the_body": ("apps/motion/user_scene.py", "    pad = BODY_REACH_M + AABB_MARGIN\n", "    pad = 0.0\n",
                                         [T + "apps/motion/test_scan_region.py::test_the_corridor_is_the_reach_ellipse_box_widened_by_the_body"]),
    "motion_floor_at_a_low_percentile": ("apps/motion/user_scene.py", "found = floor_level(column[:, 1], low_share=FLOOR_LOW_SHARE)",
                                         "found = float(np.percentile(column[:, 1], 1))",
                                         [T + "apps/motion/test_scan_region.py::test_the_floor_is_found_among_stray_points_below_it"]),
    "motion_bodies_below_the_floor": ("apps/motion/outputs.py", '"transl": _r(walk.transl[0] + up_shift)', '"transl": _r(walk.transl[0])',
                                      [T + "apps/motion/test_examples.py::test_the_readme_command_gives_bodies_meshes_and_figures"]),
    "motion_resumed_meshes_stale": ("apps/motion/cli.py",
                                    'pubs[k] = publish(recs[k], out, f"{sc.name}_{k}", label, body, save)   # meshes from the record',
                                    "pubs[k] = recs[k]",
                                    [T + "apps/motion/test_scan_region.py::test_generated_rooms_write_meshes_only_with_save_meshes_and_from_the_record"]),
    "motion_strip_hides_penetration": ("apps/motion/measures.py", "cv2.circle(img, (int(c), int(r)), 3, (220, 0, 0), -1, cv2.LINE_AA)", "None",
                                       [T + "apps/motion/test_figures.py::test_the_strip_shows_the_points_inside_the_body_in_red"]),
    "floor_up_towards_ignored": ("core/scene/floor.py", "    if towards is None:\n        lo, hi", "    if True:\n        lo, hi",
                                 [T + "apps/egohmr/test_user_checks.py::test_a_room_in_a_corner_of_a_large_floor_shows_its_floor_from_the_camera"]),
    "optim_start_ignored": ("core/optim/harness.py", "                        if it < v.start:", "                        if False:",
                            [T + "optim/test_optim.py::test_a_variable_with_a_start_is_held_until_then_and_adam_begins_afresh"]),
    "hoi_silhouette_not_relative": ("apps/hoi/losses.py", "    return chamfer / spread.clamp_min(1.0 / K[:, 0, 0] ** 2)", "    return chamfer",
                                    [T + "apps/hoi/test_losses.py::test_silhouette_is_relative_to_the_silhouettes_spread"]),
    "hoi_along_ray_keeps_the_depth": ("apps/hoi/fit.py", "    best = offsets[losses.argmin(dim=0)]", "    best = offsets[:1].expand(losses.shape[1])",
                                      [T + "apps/hoi/test_fit.py::test_along_ray_moves_the_object_to_its_depth_and_keeps_its_projection"]),
    "hoi_mesh_weight_always_w_pen": ("apps/hoi/fit.py", 'if kind == "mesh" and cfg.w_pen_mesh is not None', "if False",
                                     [T + "apps/hoi/test_fit.py::test_presets_give_the_papers_weights_and_ours"]),
    "hoi_rotation_never_held": ("apps/hoi/problem.py", 'start=self.rotation_start if who == "object" else 0', "start=0",
                                [T + "apps/hoi/test_fit.py::test_the_objects_rotation_is_held_for_its_share_of_the_steps"]),
    "hoi_scale_prior_never_free": ("apps/hoi/losses.py", "    return ((scale - prior).abs() - free).clamp_min(0.0)",
                                   "    return (scale - prior).abs()",
                                   [T + "apps/hoi/test_losses.py::test_scale_prior_is_free_within_its_band_and_pulls_at_unit_slope_beyond"]),
    "hoi_scale_band_not_the_category_spread": ("apps/hoi/problem.py", "cfg.scale_free_std * object_size_spread(c.category, c.size_m)",
                                               "cfg.scale_free_std * 0.1",
                                               [T + "apps/hoi/test_fit.py::test_presets_give_the_papers_weights_and_ours"]),
    "hoi_grid_values_unchecked": ("apps/hoi/tune.py", "                FitConfig(**{name: v})", "                pass",
                                  [T + "apps/hoi/test_tune.py::test_a_wrong_grid_is_one_line_before_the_database_is_read"]),
    "egohmr_activity_rows_of_all_frames": ("apps/egohmr/evaluate.py", 'summarize([r for r in recs if r["activity"] == a])',
                                           "summarize(recs)",
                                           [T + "apps/egohmr/test_app.py::test_by_activity_takes_each_activitys_frames_alone"]),
    "report_egohmr_activities_dropped": ("core/report/sections.py", "    if names:", "    if False:",
                                         [T + "report/test_build.py::test_egohmr_paired_difference_and_activities_from_the_apps_own_rows"]),
    "hoi_handheld_weight_ignored": ("apps/hoi/fit.py", "    hand = base if cfg.w_pen_handheld is None else cfg.w_pen_handheld",
                                    "    hand = base",
                                    [T + "apps/hoi/test_fit.py::test_penetration_weights_per_case_handheld_or_not"]),
    "hoi_user_category_never_handheld": ("apps/hoi/case.py", "    return bool(case.contacts) and all(", "    return False and all(",
                                         [T + "apps/hoi/test_fit.py::test_handheld_by_category_or_by_a_users_hand_contacts"]),
    "hoi_scale_band_for_handheld_too": ("apps/hoi/problem.py", "[0.0 if h else cfg.scale_free_std", "[cfg.scale_free_std",
                                        [T + "apps/hoi/test_fit.py::test_presets_give_the_papers_weights_and_ours"]),
    "hoi_contact_margin_ignored": ("apps/hoi/losses.py", "    if margin > 0:  # the clamp", "    if False:  # the clamp",
                                   [T + "apps/hoi/test_losses.py::test_contact_margin_counts_a_gap_within_it_as_touching"]),
    "hoi_contact_margin_not_passed": ("apps/hoi/problem.py", "tri_owner=self.tri_owner, margin=self.contact_margin)",
                                      "tri_owner=self.tri_owner)",
                                      [T + "apps/hoi/test_fit.py::test_contact_margin_reaches_every_pair_of_the_fit"]),
    "result_check_table_value_dropped_unnoticed": ("core/report/result_check.py",
                                                   "        if case in new_cases and (case, path) not in new:",
                                                   "        if False:",
                                                   [T + "report/test_result_check.py::test_a_value_only_the_fresh_run_records_is_listed_and_one_it_lacks_is_a_mismatch"]),
    "result_check_added_value_compared": ("core/report/result_check.py",
                                          "        if (case, path) not in old:  # a value later",
                                          "        if (case, path) not in old and False:  # a value later",
                                          [T + "report/test_result_check.py::test_a_value_only_the_fresh_run_records_is_listed_and_one_it_lacks_is_a_mismatch"]),
    "paired_mean_ci_of_one_side": ("apps/stats.py", "    d = a - b\n", "    d = a\n",
                                   [T + "apps/test_stats.py::test_paired_difference_is_the_interval_of_the_differences"]),
    "egohmr_support_step_may_raise_j": ("apps/egohmr/guidance.py", "free=self.last <= 0, limit=self.last)",
                                        "free=self.last <= 0, limit=None)",
                                        [T + "apps/egohmr/test_support.py::test_a_support_step_that_would_push_the_body_into_a_wall_goes_straight_down"]),
    "egohmr_support_no_vertical_fallback": ("apps/egohmr/guidance.py", 'if self.along == "free" or limit is not None:',
                                            'if self.along == "free":',
                                            [T + "apps/egohmr/test_support.py::test_a_support_step_that_would_push_the_body_into_a_wall_goes_straight_down"]),
    "refiner_onehot_of_slots": ("core/nn/code_refiner.py",
                                "ids = torch.arange(self.num_parts, device=z.device) if parts is None else parts",
                                "ids = torch.arange(self.num_parts, device=z.device)[:Kc]",
                                [T + "nn/test_code_refiner.py::test_refining_some_parts_gives_the_codes_of_refining_all"]),
    "refiner_gradient_of_the_codes_sum": ("core/nn/code_refiner.py",
                                          "(g,) = torch.autograd.grad(refinement_losses(net.output, pred, target).sum(), zg)",
                                          "(g,) = torch.autograd.grad(pred.sum(), zg)",
                                          [T + "nn/test_code_refiner.py::test_the_refiner_reads_the_gradient_of_each_parts_loss"]),
    "refiner_training_moves_every_weight": ("core/train/loop.py", "        volume.net.requires_grad_(False)\n", "",
                                            [T + "nn/test_code_refiner.py::test_training_only_the_refiner_leaves_the_encoder_and_decoders"]),
    "refiner_not_applied": ("core/volume/learned.py",
                            "z = self.net.refiner(self.net, z, xin, target, sc, parts)", "pass",
                            [T + "nn/test_code_refiner.py::test_refining_some_parts_gives_the_codes_of_refining_all"]),
}


def package_copy(root: Path) -> Path:
    """core/ -> root/volsmpl, apps/ -> root/volsmpl/apps (caches left out, assets linked); returns root."""
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "assets")
    shutil.copytree(REPO / "core", root / "volsmpl", ignore=skip)
    os.symlink(REPO / "core" / "assets", root / "volsmpl" / "assets")
    shutil.copytree(REPO / "apps", root / "volsmpl" / "apps", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return root


def target(root: Path, path: str) -> Path:
    rel = Path(path)
    return root / "volsmpl" / (rel.relative_to("core") if rel.parts[0] == "core" else Path("apps") / rel.relative_to("apps"))


def run_tests(root: Path, tests: list[str]) -> int:
    env = {**os.environ, "PYTHONPATH": str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "OMP_NUM_THREADS": "1", "PYTHONDONTWRITEBYTECODE": "1"}
    cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", *tests]
    return subprocess.run(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode


def main(argv: list[str]) -> int:
    if "--list" in argv:
        print("\n".join(MUTANTS))
        return 0
    names = argv or list(MUTANTS)
    unknown = [n for n in names if n not in MUTANTS]
    if unknown:
        print(f"unknown mutant(s) {unknown}; `python tools/mutants.py --list` names them", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="volsmpl-mutants-") as tmp:
        root = package_copy(Path(tmp))
        for name in names:  # every substitution must still match the code
            path, old, _, _ = MUTANTS[name]
            if target(root, path).read_text().count(old) != 1:
                print(f"{name}: the text to mutate is not found exactly once in {path}; update tools/mutants.py", file=sys.stderr)
                return 1
        tests = sorted({t for n in names for t in MUTANTS[n][3]})
        if run_tests(root, tests) != 0:
            print(f"baseline: the unmutated copy fails {tests}; fix that first", file=sys.stderr)
            return 1
        survived = []
        for name in names:
            path, old, new, tests = MUTANTS[name]
            f = target(root, path)
            original = f.read_text()
            f.write_text(original.replace(old, new))
            try:
                rc = run_tests(root, tests)
            finally:
                f.write_text(original)
            killed = rc not in (0, 4, 5)  # 4: usage error, 5: no tests collected
            print(f"{'killed  ' if killed else 'SURVIVED'} {name} (pytest exit {rc})", flush=True)
            if not killed:
                survived.append(name)
    print(f"{len(names) - len(survived)} of {len(names)} mutants killed" + (f"; survived: {', '.join(survived)}" if survived else ""))
    return 1 if survived else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
