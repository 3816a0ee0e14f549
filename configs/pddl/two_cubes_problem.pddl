; Two cubes from table 1 to table 2, then leave through the exit (configs/task/two_cubes.yaml),
; with the pick-and-place domain. The hand holds one item at a time (hand-empty), so every plan
; makes two trips; cube_a first and cube_b first are the two cheapest plans (9 actions each).
; Items are named as the scene's objects (scene.objects), regions as the task's parameters.
(define (problem two-cubes)
  (:domain pick-place)
  (:objects
    Table1 Table2 Exit - base_region
    CubeA_g CubeB_g - grasp_region
    CubeA_p CubeB_p - place_region
    loc_start loc_table1 loc_table2 loc_exit - site
    cube_a cube_b - item)
  (:init
    (robot-at loc_start)
    (hand-empty)
    (item-at cube_a loc_table1)
    (item-at cube_b loc_table1)
    (base-near Table1 loc_table1)
    (base-near Table2 loc_table2)
    (base-near Exit loc_exit)
    (grasps CubeA_g cube_a)
    (grasps CubeB_g cube_b)
    (place-on CubeA_p cube_a loc_table2)
    (place-on CubeB_p cube_b loc_table2))
  (:goal (and (item-at cube_a loc_table2) (item-at cube_b loc_table2) (robot-at loc_exit))))
