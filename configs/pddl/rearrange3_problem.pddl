; Three cubes from table 1 to their spots on table 2 (configs/task/rearrange3.yaml), with the
; pick-and-place domain. Each cube has its own sites at both tables (where the base parks to grasp
; it, where it parks to place it), so every trip binds its own base regions: the plan (12 actions,
; one trip per cube: move_to, grasp, move_to, place) binds each region once, and a chain of
; segments can cut it after each place (stitch.cut=after_each_place).
; Items are named as the scene's objects (scene.objects), regions as the task's parameters.
(define (problem rearrange3)
  (:domain pick-place)
  (:objects
    Table1A Table1B Table1C Table2A Table2B Table2C - base_region
    CubeA_g CubeB_g CubeC_g - grasp_region
    CubeA_p CubeB_p CubeC_p - place_region
    loc_start t1_a t1_b t1_c t2_a t2_b t2_c - site
    cube_a cube_b cube_c - item)
  (:init
    (robot-at loc_start)
    (hand-empty)
    (item-at cube_a t1_a)
    (item-at cube_b t1_b)
    (item-at cube_c t1_c)
    (base-near Table1A t1_a)
    (base-near Table1B t1_b)
    (base-near Table1C t1_c)
    (base-near Table2A t2_a)
    (base-near Table2B t2_b)
    (base-near Table2C t2_c)
    (grasps CubeA_g cube_a)
    (grasps CubeB_g cube_b)
    (grasps CubeC_g cube_c)
    (place-on CubeA_p cube_a t2_a)
    (place-on CubeB_p cube_b t2_b)
    (place-on CubeC_p cube_c t2_c))
  (:goal (and (item-at cube_a t2_a) (item-at cube_b t2_b) (item-at cube_c t2_c))))
