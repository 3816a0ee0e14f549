; Seed task: move the cube from table 1 to table 2, then leave through the exit.
; Region objects carry the task's parameter names (Table1, Cube_g, ...); sites
; are named loc_* so they never clash with a parameter (PDDL is case-insensitive).
(define (problem pick-place-seed)
  (:domain pick-place)
  (:objects
    Table1 Table2 Exit - base_region
    Cube_g - grasp_region
    Cube_p - place_region
    loc_start loc_table1 loc_table2 loc_exit - site
    cube - item)   ; named as in scene.objects
  (:init
    (robot-at loc_start)
    (hand-empty)
    (item-at cube loc_table1)
    (base-near Table1 loc_table1)
    (base-near Table2 loc_table2)
    (base-near Exit loc_exit)
    (grasps Cube_g cube)
    (place-on Cube_p cube loc_table2))
  (:goal (and (item-at cube loc_table2) (robot-at loc_exit))))
